//! The priority queue of candidate contractions: an indexed 4-ary min-heap over edge ids.
//!
//! Each live edge holds at most one entry, updated in place when its cost changes, so the heap
//! stays as small as the edge set (a lazy heap of stale copies grows several times larger and
//! spends its time in cache misses). The order is total — cost, then edge id — so equal costs
//! pop in the same order on every run. Entries hold their cost as an integer key (the bits of
//! `f64::total_cmp`'s order) beside the edge id, so sifting compares adjacent memory only.

const ABSENT: u32 = u32::MAX;
const ARITY: usize = 4;

/// A heap slot: the ordering key of the cost, then the edge id (the tie-break).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct Entry {
    key: i64,
    edge: u32,
}

/// The integer whose order is `f64::total_cmp`'s (an involution: it also maps back).
fn order_key(cost: f64) -> i64 {
    let bits = cost.to_bits() as i64;
    bits ^ ((((bits >> 63) as u64) >> 1) as i64)
}

fn cost_of_key(key: i64) -> f64 {
    f64::from_bits((key ^ ((((key >> 63) as u64) >> 1) as i64)) as u64)
}

/// Edge ids keyed by cost.
pub(crate) struct EdgeQueue {
    heap: Vec<Entry>,
    /// Edge id → its slot in `heap`, or `ABSENT`.
    slot: Vec<u32>,
}

impl EdgeQueue {
    /// An empty queue for edge ids below `edge_count`.
    #[cfg(test)]
    pub(crate) fn new(edge_count: usize) -> Self {
        Self {
            heap: Vec::with_capacity(edge_count),
            slot: vec![ABSENT; edge_count],
        }
    }

    /// A queue holding every edge id `e` below `costs.len()` at `costs[e]`, built in O(n).
    pub(crate) fn from_costs(costs: Vec<f64>) -> Self {
        let n = costs.len();
        let mut queue = Self {
            heap: costs
                .iter()
                .enumerate()
                .map(|(e, &c)| Entry {
                    key: order_key(c),
                    edge: e as u32,
                })
                .collect(),
            slot: (0..n as u32).collect(),
        };
        for i in (0..n.div_ceil(ARITY)).rev() {
            queue.sift_down(i);
        }
        queue
    }

    /// Whether edge `e` is queued.
    pub(crate) fn contains(&self, e: u32) -> bool {
        self.slot[e as usize] != ABSENT
    }

    /// Inserts edge `e` at `cost`, or moves it there if queued.
    pub(crate) fn set(&mut self, e: u32, cost: f64) {
        let key = order_key(cost);
        let i = self.slot[e as usize];
        if i == ABSENT {
            self.heap.push(Entry { key, edge: e });
            let last = self.heap.len() - 1;
            self.sift_up(last);
            return;
        }
        let i = i as usize;
        let old = self.heap[i].key;
        self.heap[i].key = key;
        if key < old {
            self.sift_up(i);
        } else if key > old {
            self.sift_down(i);
        }
    }

    /// Takes edge `e` out of the queue (no-op if absent).
    pub(crate) fn remove(&mut self, e: u32) {
        let i = self.slot[e as usize];
        if i == ABSENT {
            return;
        }
        let i = i as usize;
        self.slot[e as usize] = ABSENT;
        let Some(last) = self.heap.pop() else {
            return;
        };
        if i < self.heap.len() {
            let removed = self.heap[i];
            self.heap[i] = last;
            if last < removed {
                self.sift_up(i);
            } else {
                self.sift_down(i);
            }
        }
    }

    /// The cheapest edge and its cost, left in the queue.
    pub(crate) fn peek(&self) -> Option<(u32, f64)> {
        self.heap.first().map(|t| (t.edge, cost_of_key(t.key)))
    }

    /// Raises the cost of the cheapest edge (the one [`EdgeQueue::peek`] shows) to `cost`.
    pub(crate) fn raise_top(&mut self, cost: f64) {
        let key = order_key(cost);
        if let Some(top) = self.heap.first_mut() {
            debug_assert!(key >= top.key, "raise_top lowers a cost");
            top.key = key;
            self.sift_down(0);
        }
    }

    /// The cheapest edge and its cost, taken out of the queue.
    pub(crate) fn pop(&mut self) -> Option<(u32, f64)> {
        let top = self.peek()?;
        self.remove(top.0);
        Some(top)
    }

    fn sift_up(&mut self, mut i: usize) {
        let e = self.heap[i];
        while i > 0 {
            let parent = (i - 1) / ARITY;
            let p = self.heap[parent];
            if e >= p {
                break;
            }
            self.heap[i] = p;
            self.slot[p.edge as usize] = i as u32;
            i = parent;
        }
        self.heap[i] = e;
        self.slot[e.edge as usize] = i as u32;
    }

    fn sift_down(&mut self, mut i: usize) {
        let e = self.heap[i];
        let n = self.heap.len();
        loop {
            let first = ARITY * i + 1;
            if first >= n {
                break;
            }
            let children = &self.heap[first..(first + ARITY).min(n)];
            let mut best = 0;
            for (c, child) in children.iter().enumerate().skip(1) {
                if *child < children[best] {
                    best = c;
                }
            }
            let b = children[best];
            if b >= e {
                break;
            }
            self.heap[i] = b;
            self.slot[b.edge as usize] = i as u32;
            i = first + best;
        }
        self.heap[i] = e;
        self.slot[e.edge as usize] = i as u32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pops_in_cost_then_id_order_after_updates_and_removals() {
        // A deterministic pseudo-random workload checked against sorting.
        let n = 500u32;
        let mut q = EdgeQueue::new(n as usize);
        let mut reference: Vec<Option<f64>> = vec![None; n as usize];
        let mut x = 12345u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for _ in 0..3000 {
            let e = (next() % n as u64) as u32;
            match next() % 4 {
                0 => {
                    q.remove(e);
                    reference[e as usize] = None;
                }
                _ => {
                    // Few distinct costs, so ties by id are exercised.
                    let c = (next() % 50) as f64 * 0.5;
                    q.set(e, c);
                    reference[e as usize] = Some(c);
                }
            }
        }
        let mut expected: Vec<(f64, u32)> = reference
            .iter()
            .enumerate()
            .filter_map(|(e, c)| c.map(|c| (c, e as u32)))
            .collect();
        expected.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let popped: Vec<(f64, u32)> = std::iter::from_fn(|| q.pop())
            .map(|(e, c)| (c, e))
            .collect();
        assert_eq!(popped, expected);
    }

    #[test]
    fn bulk_build_pops_in_order() {
        let costs: Vec<f64> = (0..1000).map(|i| ((i * 7919) % 101) as f64).collect();
        let mut q = EdgeQueue::from_costs(costs.clone());
        assert!(q.contains(999));
        let mut expected: Vec<(f64, u32)> = costs
            .iter()
            .enumerate()
            .map(|(e, &c)| (c, e as u32))
            .collect();
        expected.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let popped: Vec<(f64, u32)> = std::iter::from_fn(|| q.pop())
            .map(|(e, c)| (c, e))
            .collect();
        assert_eq!(popped, expected);
        assert!(!q.contains(999));
    }

    #[test]
    fn raising_the_top_reorders_like_a_fresh_insert() {
        let costs = vec![3.0, 1.0, 2.0, 1.0, 0.5];
        let mut q = EdgeQueue::from_costs(costs);
        assert_eq!(q.peek(), Some((4, 0.5)));
        q.raise_top(2.0); // ties with edge 2: the lower id goes first
        assert_eq!(q.peek(), Some((1, 1.0)));
        q.raise_top(5.0);
        let popped: Vec<(u32, f64)> = std::iter::from_fn(|| q.pop()).collect();
        assert_eq!(
            popped,
            vec![(3, 1.0), (2, 2.0), (4, 2.0), (0, 3.0), (1, 5.0)]
        );
    }

    #[test]
    fn order_keys_sort_like_total_cmp_and_map_back() {
        let mut values = [
            f64::NEG_INFINITY,
            -2.5,
            -0.0,
            0.0,
            1e-300,
            3.0,
            f64::INFINITY,
            f64::NAN,
        ];
        values.sort_by(f64::total_cmp);
        let keys: Vec<i64> = values.iter().map(|&c| order_key(c)).collect();
        assert!(keys.windows(2).all(|w| w[0] < w[1]));
        for (&c, &k) in values.iter().zip(&keys) {
            assert_eq!(cost_of_key(k).to_bits(), c.to_bits());
        }
    }
}
