//! The priority queue of candidate contractions: an indexed 4-ary min-heap over edge ids.
//!
//! Each live edge holds at most one entry, updated in place when its cost changes, so the heap
//! stays as small as the edge set (a lazy heap of stale copies grows several times larger and
//! spends its time in cache misses). The order is total — cost, then edge id — so equal costs
//! pop in the same order on every run. An entry is one `u128`: the cost as an integer key (the
//! bits of `f64::total_cmp`'s order) above the edge id, so one integer comparison orders two
//! entries. The four children of a node share one 64-byte cache line: the buffer starts with
//! up to three unused entries chosen for that from its address.

const ABSENT: u32 = u32::MAX;
const ARITY: usize = 4;
/// Entries per cache line.
const LINE: usize = 64 / size_of::<u128>();

/// The integer whose order is `f64::total_cmp`'s (an involution: it also maps back).
fn order_key(cost: f64) -> i64 {
    let bits = cost.to_bits() as i64;
    bits ^ ((((bits >> 63) as u64) >> 1) as i64)
}

fn cost_of_key(key: i64) -> f64 {
    f64::from_bits((key ^ ((((key >> 63) as u64) >> 1) as i64)) as u64)
}

/// The heap entry of `edge` at `cost`: the key, made unsigned with the same order, above the id.
fn entry(cost: f64, edge: u32) -> u128 {
    let key = (order_key(cost) as u64) ^ (1 << 63);
    (u128::from(key) << 32) | u128::from(edge)
}

fn edge_of(entry: u128) -> u32 {
    entry as u32
}

fn cost_of_entry(entry: u128) -> f64 {
    cost_of_key((((entry >> 32) as u64) ^ (1 << 63)) as i64)
}

/// Edge ids keyed by cost.
pub(crate) struct EdgeQueue {
    /// `pad` unused entries, then the heap. Never reallocated (the capacity is set up front),
    /// so the alignment chosen from the address holds.
    buffer: Vec<u128>,
    pad: usize,
    /// Edge id → its slot in the heap, or `ABSENT`.
    slot: Vec<u32>,
}

impl EdgeQueue {
    /// An empty queue for edge ids below `edge_count`.
    #[cfg(test)]
    pub(crate) fn new(edge_count: usize) -> Self {
        Self::with_entries(std::iter::empty(), edge_count)
    }

    /// Room for `edge_count` entries after a padding that puts every node's children (slots
    /// 4i + 1 to 4i + 4) in one cache line; `entries` (at most `edge_count`) fill the heap
    /// unordered.
    fn with_entries(entries: impl Iterator<Item = u128>, edge_count: usize) -> Self {
        let mut buffer: Vec<u128> = Vec::with_capacity(edge_count + LINE);
        // Slot 1 (the root's first child) must start a line.
        let first_child = buffer.as_ptr() as usize / size_of::<u128>() + 1;
        let pad = (LINE - first_child % LINE) % LINE;
        buffer.resize(pad, 0);
        buffer.extend(entries);
        debug_assert!(buffer.len() <= edge_count + LINE);
        Self {
            buffer,
            pad,
            slot: vec![ABSENT; edge_count],
        }
    }

    /// A queue holding every edge id `e` below `costs.len()` at the `e`-th cost, built in O(n).
    pub(crate) fn from_costs(costs: impl ExactSizeIterator<Item = f64>) -> Self {
        let n = costs.len();
        let entries = costs.enumerate().map(|(e, c)| entry(c, e as u32));
        let mut queue = Self::with_entries(entries, n);
        for (e, s) in queue.slot.iter_mut().enumerate() {
            *s = e as u32;
        }
        for i in (0..n.div_ceil(ARITY)).rev() {
            queue.sift_down(i);
        }
        queue
    }

    fn len(&self) -> usize {
        self.buffer.len() - self.pad
    }

    /// Whether edge `e` is queued.
    pub(crate) fn contains(&self, e: u32) -> bool {
        self.slot[e as usize] != ABSENT
    }

    /// Asks for edge `e`'s slot and entry.
    pub(crate) fn prefetch(&self, e: u32) {
        let i = self.slot[e as usize];
        if let Some(entry) = self
            .buffer
            .get(self.pad + i as usize)
            .filter(|_| i != ABSENT)
        {
            crate::prefetch::prefetch(entry);
        }
    }

    /// The edges in the root's children: the likely next tops.
    pub(crate) fn next_tops(&self) -> impl Iterator<Item = u32> + '_ {
        let heap = &self.buffer[self.pad..];
        heap.get(1..heap.len().min(1 + ARITY))
            .unwrap_or(&[])
            .iter()
            .map(|&e| edge_of(e))
    }

    /// Asks for edge `e`'s slot.
    pub(crate) fn prefetch_slot(&self, e: u32) {
        crate::prefetch::prefetch(&self.slot[e as usize]);
    }

    /// Inserts edge `e` at `cost`, or moves it there if queued.
    pub(crate) fn set(&mut self, e: u32, cost: f64) {
        let new = entry(cost, e);
        let i = self.slot[e as usize];
        if i == ABSENT {
            self.buffer.push(new);
            self.sift_up(self.len() - 1, new);
            return;
        }
        let i = i as usize;
        let old = self.buffer[self.pad + i];
        if new < old {
            self.sift_up(i, new);
        } else if new > old {
            self.buffer[self.pad + i] = new;
            self.sift_down(i);
        }
    }

    /// Takes edge `e` out of the queue (no-op if absent).
    pub(crate) fn remove(&mut self, e: u32) {
        let i = self.slot[e as usize];
        if i == ABSENT {
            return;
        }
        self.slot[e as usize] = ABSENT;
        self.remove_at(i as usize);
    }

    /// Fills slot `i` (whose edge is already marked absent) with the last entry.
    fn remove_at(&mut self, i: usize) {
        let removed = self.buffer[self.pad + i];
        let Some(last) = self.buffer.pop() else {
            return;
        };
        if i < self.len() {
            if last < removed {
                self.sift_up(i, last);
            } else {
                self.buffer[self.pad + i] = last;
                self.sift_down(i);
            }
        }
    }

    /// The cheapest edge and its cost, left in the queue.
    pub(crate) fn peek(&self) -> Option<(u32, f64)> {
        let top = *self.buffer.get(self.pad)?;
        Some((edge_of(top), cost_of_entry(top)))
    }

    /// Raises the cost of the cheapest edge (the one [`EdgeQueue::peek`] shows) to `cost`.
    pub(crate) fn raise_top(&mut self, cost: f64) {
        if let Some(&top) = self.buffer.get(self.pad) {
            let new = entry(cost, edge_of(top));
            debug_assert!(new >= top, "raise_top lowers a cost");
            self.buffer[self.pad] = new;
            self.sift_down(0);
        }
    }

    /// The cheapest edge and its cost, taken out of the queue.
    pub(crate) fn pop(&mut self) -> Option<(u32, f64)> {
        let top = self.peek()?;
        self.slot[top.0 as usize] = ABSENT;
        self.remove_at(0);
        Some(top)
    }

    /// Moves `e` up from slot `i` to its place, and puts it there.
    fn sift_up(&mut self, mut i: usize, e: u128) {
        let heap = &mut self.buffer[self.pad..];
        while i > 0 {
            let parent = (i - 1) / ARITY;
            let p = heap[parent];
            if e >= p {
                break;
            }
            heap[i] = p;
            self.slot[edge_of(p) as usize] = i as u32;
            i = parent;
        }
        heap[i] = e;
        self.slot[edge_of(e) as usize] = i as u32;
    }

    /// Moves the entry at slot `i` down to its place.
    fn sift_down(&mut self, mut i: usize) {
        let heap = &mut self.buffer[self.pad..];
        let e = heap[i];
        let n = heap.len();
        loop {
            let first = ARITY * i + 1;
            if first >= n {
                break;
            }
            // The grandchildren's lines, so that the next level's comparisons need not wait.
            if let Some(grandchild) = heap.get(ARITY * first + 1..) {
                let mut offset = 0;
                while offset < ARITY * ARITY && offset < grandchild.len() {
                    crate::prefetch::prefetch(&grandchild[offset]);
                    offset += LINE;
                }
            }
            let (mut best, mut at) = (heap[first], first);
            if let Some(children) = heap.get(first + 1..first + ARITY) {
                // A full set of children: no bounds to test.
                for (c, &child) in children.iter().enumerate() {
                    if child < best {
                        (best, at) = (child, first + 1 + c);
                    }
                }
            } else {
                for (c, &child) in heap[first + 1..n].iter().enumerate() {
                    if child < best {
                        (best, at) = (child, first + 1 + c);
                    }
                }
            }
            if best >= e {
                break;
            }
            heap[i] = best;
            self.slot[edge_of(best) as usize] = i as u32;
            i = at;
        }
        heap[i] = e;
        self.slot[edge_of(e) as usize] = i as u32;
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
        let mut q = EdgeQueue::from_costs(costs.iter().copied());
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
        let mut q = EdgeQueue::from_costs(costs.into_iter());
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
    fn children_share_a_cache_line() {
        for n in [1, 5, 100, 1000] {
            let q = EdgeQueue::from_costs(std::iter::repeat_n(1.0, n));
            let first_child = q.buffer.as_ptr() as usize + size_of::<u128>() * (q.pad + 1);
            assert_eq!(first_child % 64, 0);
            assert!(q.pad < LINE);
        }
    }

    #[test]
    fn entries_order_like_cost_then_edge() {
        let costs = [0.0, 1e-300, 0.5, 3.0, f64::INFINITY];
        for w in costs.windows(2) {
            assert!(entry(w[0], u32::MAX) < entry(w[1], 0));
            assert_eq!(cost_of_entry(entry(w[1], 7)), w[1]);
            assert_eq!(edge_of(entry(w[1], 7)), 7);
        }
        assert!(entry(2.0, 3) < entry(2.0, 4));
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
