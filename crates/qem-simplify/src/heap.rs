//! The priority queue of candidate contractions: an indexed 4-ary min-heap over edge ids.
//!
//! Each live edge holds at most one entry, updated in place when its cost changes, so the heap
//! stays as small as the edge set (a lazy heap of stale copies grows several times larger and
//! spends its time in cache misses). The order is total — cost, then edge id — so equal costs
//! pop in the same order on every run.

const ABSENT: u32 = u32::MAX;
const ARITY: usize = 4;

/// Edge ids keyed by cost.
pub(crate) struct EdgeQueue {
    heap: Vec<u32>,
    /// Edge id → its slot in `heap`, or `ABSENT`.
    slot: Vec<u32>,
    cost: Vec<f64>,
}

impl EdgeQueue {
    /// An empty queue for edge ids below `edge_count`.
    #[cfg(test)]
    pub(crate) fn new(edge_count: usize) -> Self {
        Self {
            heap: Vec::with_capacity(edge_count),
            slot: vec![ABSENT; edge_count],
            cost: vec![0.0; edge_count],
        }
    }

    /// A queue holding every edge id `e` below `costs.len()` at `costs[e]`, built in O(n).
    pub(crate) fn from_costs(cost: Vec<f64>) -> Self {
        let n = cost.len();
        let mut queue = Self {
            heap: (0..n as u32).collect(),
            slot: (0..n as u32).collect(),
            cost,
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

    fn less(&self, a: u32, b: u32) -> bool {
        match self.cost[a as usize].total_cmp(&self.cost[b as usize]) {
            std::cmp::Ordering::Less => true,
            std::cmp::Ordering::Greater => false,
            std::cmp::Ordering::Equal => a < b,
        }
    }

    /// Inserts edge `e` at `cost`, or moves it there if queued.
    pub(crate) fn set(&mut self, e: u32, cost: f64) {
        let i = self.slot[e as usize];
        if i != ABSENT && self.cost[e as usize].total_cmp(&cost).is_eq() {
            return;
        }
        self.cost[e as usize] = cost;
        if i == ABSENT {
            self.heap.push(e);
            let last = self.heap.len() - 1;
            self.slot[e as usize] = last as u32;
            self.sift_up(last);
        } else {
            let i = self.sift_up(i as usize);
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
        let last = self.heap.pop().unwrap_or(e);
        if i < self.heap.len() {
            self.heap[i] = last;
            self.slot[last as usize] = i as u32;
            let i = self.sift_up(i);
            self.sift_down(i);
        }
    }

    /// The cheapest edge and its cost, taken out of the queue.
    pub(crate) fn pop(&mut self) -> Option<(u32, f64)> {
        let &top = self.heap.first()?;
        self.remove(top);
        Some((top, self.cost[top as usize]))
    }

    fn sift_up(&mut self, mut i: usize) -> usize {
        let e = self.heap[i];
        while i > 0 {
            let parent = (i - 1) / ARITY;
            let p = self.heap[parent];
            if !self.less(e, p) {
                break;
            }
            self.heap[i] = p;
            self.slot[p as usize] = i as u32;
            i = parent;
        }
        self.heap[i] = e;
        self.slot[e as usize] = i as u32;
        i
    }

    fn sift_down(&mut self, mut i: usize) {
        let e = self.heap[i];
        let n = self.heap.len();
        loop {
            let first = ARITY * i + 1;
            if first >= n {
                break;
            }
            let mut best = first;
            for c in first + 1..(first + ARITY).min(n) {
                if self.less(self.heap[c], self.heap[best]) {
                    best = c;
                }
            }
            let b = self.heap[best];
            if !self.less(b, e) {
                break;
            }
            self.heap[i] = b;
            self.slot[b as usize] = i as u32;
            i = best;
        }
        self.heap[i] = e;
        self.slot[e as usize] = i as u32;
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
}
