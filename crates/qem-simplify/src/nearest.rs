//! Closest-point queries over triangles, with segments and points as degenerate triangles: where
//! on the template a remeshed vertex belongs, which fine vertex seeds a cluster, and how far a
//! fine vertex lies from a simplified surface (the geometric error of the reports).

pub(crate) use crate::geometry::closest_point_on_triangle as closest_on_triangle;
use crate::geometry::{Vec3, dot, sub};

/// The closest point of one item to a query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Closest {
    pub point: Vec3,
    /// The item's id (as given to [`NearestGrid::new`]).
    pub id: u32,
    pub distance_squared: f64,
}

/// Items bucketed by every grid cell their bounding box overlaps. An item not met by the time
/// the search has covered a box of cells around the query lies wholly outside that box: the
/// search stops once the query's distance to the box's walls passes the best distance found.
pub(crate) struct NearestGrid {
    items: Vec<[Vec3; 3]>,
    ids: Vec<u32>,
    origin: Vec3,
    cell: f64,
    dims: [usize; 3],
    /// CSR: the items of cell c are `order[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    order: Vec<u32>,
}

impl NearestGrid {
    /// A grid over `items` (triangles; a segment is `[a, b, b]`, a point `[p, p, p]`), item k
    /// answering to `ids[k]`.
    pub(crate) fn new(items: Vec<[Vec3; 3]>, ids: Vec<u32>) -> Self {
        debug_assert_eq!(items.len(), ids.len());
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut extent_sum = 0.0;
        for t in &items {
            let (tlo, thi) = item_box(t);
            extent_sum += (0..3).map(|k| thi[k] - tlo[k]).fold(0.0, f64::max);
            for k in 0..3 {
                lo[k] = lo[k].min(tlo[k]);
                hi[k] = hi[k].max(thi[k]);
            }
        }
        if items.is_empty() {
            (lo, hi) = ([0.0; 3], [0.0; 3]);
        }
        let span = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        // Cells about an item's size, at most ~8 per item in all.
        let mut cell = (extent_sum / items.len().max(1) as f64)
            .max(span * 1e-3)
            .max(1e-30);
        let dims_for = |cell: f64| [0, 1, 2].map(|k| ((hi[k] - lo[k]) / cell) as usize + 1);
        let mut dims = dims_for(cell);
        while dims.iter().product::<usize>() > 8 * items.len() + 64 {
            cell *= 1.25;
            dims = dims_for(cell);
        }
        let mut grid = Self {
            items,
            ids,
            origin: lo,
            cell,
            dims,
            start: Vec::new(),
            order: Vec::new(),
        };
        grid.fill();
        grid
    }

    fn fill(&mut self) {
        let cells = self.dims.iter().product::<usize>();
        let ranges: Vec<[[usize; 3]; 2]> = self
            .items
            .iter()
            .map(|t| {
                let (lo, hi) = item_box(t);
                [self.cell_of(lo), self.cell_of(hi)]
            })
            .collect();
        let mut start = vec![0u32; cells + 1];
        for r in &ranges {
            self.for_cells(r, |c| start[c + 1] += 1);
        }
        for c in 0..cells {
            start[c + 1] += start[c];
        }
        let mut cursor = start.clone();
        let mut order = vec![0u32; start[cells] as usize];
        for (k, r) in ranges.iter().enumerate() {
            self.for_cells(r, |c| {
                order[cursor[c] as usize] = k as u32;
                cursor[c] += 1;
            });
        }
        self.start = start;
        self.order = order;
    }

    fn for_cells(&self, [lo, hi]: &[[usize; 3]; 2], mut f: impl FnMut(usize)) {
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    f(self.index([x, y, z]));
                }
            }
        }
    }

    fn index(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    /// The cell of `p`, clamped into the grid.
    fn cell_of(&self, p: Vec3) -> [usize; 3] {
        [0, 1, 2].map(|k| {
            let i = ((p[k] - self.origin[k]) / self.cell).floor();
            if i.is_nan() {
                0
            } else {
                (i.max(0.0) as usize).min(self.dims[k] - 1)
            }
        })
    }

    /// How many items the grid holds.
    pub(crate) fn len(&self) -> usize {
        self.items.len()
    }

    /// The closest point to `p` over the items whose id `accept` admits; `None` when it admits
    /// none. Equal distances go to the lower id (among the items visited, in a fixed order: the
    /// answer is deterministic).
    pub(crate) fn closest(&self, p: Vec3, accept: impl Fn(u32) -> bool) -> Option<Closest> {
        self.closest_within(p, f64::INFINITY, accept)
    }

    /// [`NearestGrid::closest`] among the items within `limit` of `p` only (a shorter search).
    pub(crate) fn closest_within(
        &self,
        p: Vec3,
        limit: f64,
        accept: impl Fn(u32) -> bool,
    ) -> Option<Closest> {
        let c = self.cell_of(p);
        let mut best: Option<Closest> = None;
        for r in 0.. {
            let lo = c.map(|x| x as isize - r);
            let hi = c.map(|x| x as isize + r);
            for z in lo[2].max(0)..=hi[2].min(self.dims[2] as isize - 1) {
                for y in lo[1].max(0)..=hi[1].min(self.dims[1] as isize - 1) {
                    // Inside the shell only x = lo and x = hi are new.
                    let on_shell = z == lo[2] || z == hi[2] || y == lo[1] || y == hi[1];
                    let step = if on_shell { 1 } else { (2 * r).max(1) };
                    let mut x = lo[0];
                    while x <= hi[0] {
                        if x >= 0 && x < self.dims[0] as isize {
                            let cell = self.index([x as usize, y as usize, z as usize]);
                            self.visit(cell, p, &accept, &mut best);
                        }
                        x += step;
                    }
                }
            }
            // The distance from p to the nearest wall of the searched box with cells beyond.
            let mut wall = f64::INFINITY;
            for k in 0..3 {
                if lo[k] > 0 {
                    wall = wall.min(p[k] - (self.origin[k] + lo[k] as f64 * self.cell));
                }
                if hi[k] < self.dims[k] as isize - 1 {
                    wall = wall.min(self.origin[k] + (hi[k] + 1) as f64 * self.cell - p[k]);
                }
            }
            if wall.is_infinite() || wall >= limit {
                break;
            }
            if let Some(b) = &best
                && b.distance_squared <= wall.max(0.0).powi(2)
            {
                break;
            }
        }
        best.filter(|b| b.distance_squared <= limit * limit)
    }

    fn visit(
        &self,
        cell: usize,
        p: Vec3,
        accept: &impl Fn(u32) -> bool,
        best: &mut Option<Closest>,
    ) {
        let range = self.start[cell] as usize..self.start[cell + 1] as usize;
        for &k in &self.order[range] {
            let id = self.ids[k as usize];
            if !accept(id) {
                continue;
            }
            let [a, b, c] = self.items[k as usize];
            let point = closest_on_triangle(p, a, b, c);
            let d = sub(p, point);
            let distance_squared = dot(d, d);
            let better = match best {
                None => true,
                Some(old) => (distance_squared, id) < (old.distance_squared, old.id),
            };
            if better {
                *best = Some(Closest {
                    point,
                    id,
                    distance_squared,
                });
            }
        }
    }
}

fn item_box(t: &[Vec3; 3]) -> (Vec3, Vec3) {
    let lo = [0, 1, 2].map(|k| t[0][k].min(t[1][k]).min(t[2][k]));
    let hi = [0, 1, 2].map(|k| t[0][k].max(t[1][k]).max(t[2][k]));
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::add;

    /// A deterministic pseudo-random number in [0, 1) (xorshift).
    fn uniform(state: &mut u64) -> f64 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn grid_answers_like_brute_force_with_a_filter() {
        let mut state = 0x2545f4914f6cdd1d;
        let mut items = Vec::new();
        for _ in 0..300 {
            let c = [0, 1, 2].map(|_| 10.0 * uniform(&mut state));
            let t: [Vec3; 3] =
                std::array::from_fn(|_| add(c, [0, 1, 2].map(|_| uniform(&mut state) - 0.5)));
            items.push(t);
        }
        // Points and a large triangle among small ones.
        items.push([[1.0, 1.0, 1.0]; 3]);
        items.push([[0.0, 0.0, 5.0], [10.0, 0.0, 5.0], [0.0, 10.0, 5.0]]);
        let ids: Vec<u32> = (0..items.len() as u32).map(|k| 1000 + k).collect();
        let grid = NearestGrid::new(items.clone(), ids);
        for k in 0..300 {
            let p = [0, 1, 2].map(|_| 14.0 * uniform(&mut state) - 2.0);
            let accept = |id: u32| id % 3 != k % 3;
            let brute = items
                .iter()
                .enumerate()
                .filter(|&(i, _)| accept(1000 + i as u32))
                .map(|(_, t)| {
                    let q = closest_on_triangle(p, t[0], t[1], t[2]);
                    dot(sub(p, q), sub(p, q))
                })
                .fold(f64::INFINITY, f64::min);
            let found = grid.closest(p, accept).expect("some item accepted");
            assert!(accept(found.id));
            assert!((found.distance_squared - brute).abs() <= 1e-12 * (1.0 + brute));
        }
        assert!(grid.closest([0.0; 3], |_| false).is_none());
    }

    #[test]
    fn queries_far_outside_the_grid_find_the_nearest_triangle() {
        // Triangles on a wavy sheet; queries above and below it and far outside its box.
        let h = |x: f64, y: f64| 0.3 * (x * 0.7).sin() * (y * 0.5).cos();
        let mut items = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
                items.push([
                    [x, y, h(x, y)],
                    [x + 0.5, y, h(x + 0.5, y)],
                    [x, y + 0.4, 0.1],
                ]);
            }
        }
        let grid = NearestGrid::new(items.clone(), (0..items.len() as u32).collect());
        let queries = (0..200)
            .map(|k| {
                let t = k as f64;
                [
                    12.0 * (0.13 * t).sin().abs(),
                    11.0 * (0.29 * t).cos().abs(),
                    2.0 * (0.7 * t).sin(),
                ]
            })
            .chain([[30.0, -5.0, 4.0], [-3.0, -3.0, -3.0], [5.0, 5.0, 40.0]]);
        for p in queries {
            let brute = items
                .iter()
                .map(|t| {
                    let q = closest_on_triangle(p, t[0], t[1], t[2]);
                    dot(sub(p, q), sub(p, q))
                })
                .fold(f64::INFINITY, f64::min);
            let found = grid.closest(p, |_| true).expect("the grid is not empty");
            assert_eq!(found.distance_squared, brute, "at {p:?}");
        }
    }
}
