//! One growable list per vertex, all in one flat buffer: the per-vertex faces and edges of the
//! mesh under contraction. Against a `Vec` per vertex this saves an allocation per vertex (and
//! per growth), and keeps neighbouring vertices' lists close in memory.

/// Where one list lives in the buffer.
#[derive(Debug, Clone, Copy)]
struct Span {
    start: u32,
    len: u32,
    cap: u32,
}

/// Lists indexed by vertex. A list that outgrows its room moves to the end of the buffer with
/// twice the room; the room it leaves is not reused (lists only grow by merges, a few times).
#[derive(Debug, Clone)]
pub(crate) struct Lists<T> {
    spans: Vec<Span>,
    items: Vec<T>,
}

impl<T: Copy> Lists<T> {
    /// `lists.len()` lists holding `lists[i]`, each with room for `slack` more items.
    #[cfg(test)]
    pub(crate) fn from_lists<'a>(
        lists: impl ExactSizeIterator<Item = &'a [T]>,
        slack: usize,
    ) -> Self
    where
        T: 'a,
    {
        let mut spans = Vec::with_capacity(lists.len());
        let mut items = Vec::new();
        for list in lists {
            let start = items.len() as u32;
            items.extend_from_slice(list);
            // Filler up to the room; never read (len bounds every access).
            if let Some(&fill) = list.first() {
                items.extend(std::iter::repeat_n(fill, slack));
            }
            spans.push(Span {
                start,
                len: list.len() as u32,
                cap: (items.len() as u32) - start,
            });
        }
        Self { spans, items }
    }

    /// Empty lists with room for `lengths[i]` + `slack` items each (the room filled with
    /// `fill`, never read), to be filled by [`Lists::push`] without moving.
    pub(crate) fn with_room(lengths: &[u32], slack: usize, fill: T) -> Self {
        let mut start = 0u32;
        let spans = lengths
            .iter()
            .map(|&len| {
                let span = Span {
                    start,
                    len: 0,
                    cap: len + slack as u32,
                };
                start += span.cap;
                span
            })
            .collect();
        Self {
            spans,
            items: vec![fill; start as usize],
        }
    }

    /// The number of lists.
    pub(crate) fn len(&self) -> usize {
        self.spans.len()
    }

    /// List `v`.
    pub(crate) fn get(&self, v: u32) -> &[T] {
        let s = self.spans[v as usize];
        &self.items[s.start as usize..(s.start + s.len) as usize]
    }

    /// Asks for where list `v` is kept.
    pub(crate) fn prefetch_span(&self, v: u32) {
        crate::prefetch::prefetch(&self.spans[v as usize]);
    }

    /// Asks for list `v`'s first items.
    pub(crate) fn prefetch_items(&self, v: u32) {
        let s = self.spans[v as usize];
        if let Some(first) = self.items.get(s.start as usize) {
            crate::prefetch::prefetch(first);
        }
    }

    /// List `v`, mutable.
    pub(crate) fn get_mut(&mut self, v: u32) -> &mut [T] {
        let s = self.spans[v as usize];
        &mut self.items[s.start as usize..(s.start + s.len) as usize]
    }

    /// Appends `x` to list `v`.
    pub(crate) fn push(&mut self, v: u32, x: T) {
        let s = self.spans[v as usize];
        if s.len == s.cap {
            let start = self.items.len();
            let cap = (2 * s.cap).max(4);
            self.items
                .extend_from_within(s.start as usize..(s.start + s.len) as usize);
            self.items
                .extend(std::iter::repeat_n(x, (cap - s.len) as usize));
            self.spans[v as usize] = Span {
                start: start as u32,
                len: s.len,
                cap,
            };
        }
        let s = &mut self.spans[v as usize];
        self.items[(s.start + s.len) as usize] = x;
        s.len += 1;
    }

    /// Keeps the items of list `v` for which `keep` holds, in order.
    pub(crate) fn retain(&mut self, v: u32, mut keep: impl FnMut(&T) -> bool) {
        let s = self.spans[v as usize];
        let list = &mut self.items[s.start as usize..(s.start + s.len) as usize];
        let mut kept = 0;
        for i in 0..list.len() {
            if keep(&list[i]) {
                list[kept] = list[i];
                kept += 1;
            }
        }
        self.spans[v as usize].len = kept as u32;
    }

    /// Moves list `v`'s items into `out` (cleared first), leaving it empty.
    pub(crate) fn take_into(&mut self, v: u32, out: &mut Vec<T>) {
        out.clear();
        out.extend_from_slice(self.get(v));
        self.spans[v as usize].len = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_made_with_room_fill_without_moving() {
        let mut lists = Lists::with_room(&[2, 0, 3], 1, 0u32);
        let before = lists.items.len();
        for (v, x) in [(0, 5), (2, 7), (0, 6), (2, 8), (2, 9), (1, 4)] {
            lists.push(v, x);
        }
        assert_eq!(lists.items.len(), before, "no list moved");
        assert_eq!(lists.get(0), &[5, 6]);
        assert_eq!(lists.get(1), &[4]);
        assert_eq!(lists.get(2), &[7, 8, 9]);
    }

    #[test]
    fn behaves_like_a_vec_per_list() {
        // A deterministic workload against Vec<Vec<u32>>, with growth past every room.
        let initial: Vec<Vec<u32>> = (0..7).map(|i| (0..i).collect()).collect();
        let mut lists = Lists::from_lists(initial.iter().map(Vec::as_slice), 1);
        let mut reference = initial.clone();
        let mut x = 99u64;
        let mut scratch = Vec::new();
        for step in 0..2000u32 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let v = (x % 7) as u32;
            match (x >> 8) % 5 {
                0 => {
                    lists.retain(v, |&y| y % 3 != step % 3);
                    reference[v as usize].retain(|&y| y % 3 != step % 3);
                }
                1 if x.is_multiple_of(11) => {
                    lists.take_into(v, &mut scratch);
                    assert_eq!(scratch, std::mem::take(&mut reference[v as usize]));
                }
                _ => {
                    lists.push(v, step);
                    reference[v as usize].push(step);
                }
            }
            if let Some(first) = lists.get_mut(v).first_mut() {
                *first += 1;
                reference[v as usize][0] += 1;
            }
            for (i, r) in reference.iter().enumerate() {
                assert_eq!(lists.get(i as u32), r.as_slice(), "list {i} at step {step}");
            }
        }
        assert_eq!(lists.len(), 7);
    }
}
