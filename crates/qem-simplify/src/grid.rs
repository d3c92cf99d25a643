//! A uniform grid over triangles for nearest-surface queries (the geometric error).

use crate::geometry::{Vec3, point_triangle_distance_squared};

/// Triangles bucketed by the grid cells their bounding boxes overlap.
pub(crate) struct TriangleGrid {
    triangles: Vec<[Vec3; 3]>,
    origin: Vec3,
    cell: f64,
    dims: [usize; 3],
    /// CSR: the triangles of cell c are `items[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    items: Vec<u32>,
}

impl TriangleGrid {
    /// A grid holding `triangles` whose box also covers `extra` points (the query points, so
    /// every query starts inside the grid). Needs at least one triangle.
    pub(crate) fn new(triangles: Vec<[Vec3; 3]>, extra: &[Vec3]) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut extent_sum = 0.0;
        for t in &triangles {
            let (tlo, thi) = tri_box(t);
            extent_sum += (0..3).map(|k| thi[k] - tlo[k]).fold(0.0, f64::max);
            for k in 0..3 {
                lo[k] = lo[k].min(tlo[k]);
                hi[k] = hi[k].max(thi[k]);
            }
        }
        for p in extra {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let span = (0..3)
            .map(|k| hi[k] - lo[k])
            .fold(0.0, f64::max)
            .max(1e-300);
        // Cells about the size of a triangle, but never more than ~8 per triangle in all.
        let mut cell = (extent_sum / triangles.len().max(1) as f64).max(span * 1e-3);
        let dims_for =
            |cell: f64| [0, 1, 2].map(|k| (((hi[k] - lo[k]) / cell) as usize + 1).max(1));
        let mut dims = dims_for(cell);
        while dims.iter().product::<usize>() > 8 * triangles.len().max(1) + 64 {
            cell *= 1.5;
            dims = dims_for(cell);
        }
        let mut grid = Self {
            triangles,
            origin: lo,
            cell,
            dims,
            start: Vec::new(),
            items: Vec::new(),
        };
        grid.fill();
        grid
    }

    fn fill(&mut self) {
        let cells = self.dims.iter().product::<usize>();
        let mut count = vec![0u32; cells + 1];
        let ranges: Vec<[[usize; 2]; 3]> = self
            .triangles
            .iter()
            .map(|t| {
                let (lo, hi) = tri_box(t);
                let (a, b) = (self.cell_of(lo), self.cell_of(hi));
                [[a[0], b[0]], [a[1], b[1]], [a[2], b[2]]]
            })
            .collect();
        for r in &ranges {
            self.for_cells(r, |c| count[c + 1] += 1);
        }
        for c in 0..cells {
            count[c + 1] += count[c];
        }
        let mut cursor = count.clone();
        let mut items = vec![0u32; count[cells] as usize];
        for (t, r) in ranges.iter().enumerate() {
            self.for_cells(r, |c| {
                items[cursor[c] as usize] = t as u32;
                cursor[c] += 1;
            });
        }
        self.start = count;
        self.items = items;
    }

    fn for_cells(&self, r: &[[usize; 2]; 3], mut f: impl FnMut(usize)) {
        for z in r[2][0]..=r[2][1] {
            for y in r[1][0]..=r[1][1] {
                for x in r[0][0]..=r[0][1] {
                    f(self.index([x, y, z]));
                }
            }
        }
    }

    fn index(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    fn cell_of(&self, p: Vec3) -> [usize; 3] {
        [0, 1, 2].map(|k| {
            let i = ((p[k] - self.origin[k]) / self.cell).floor();
            (i.max(0.0) as usize).min(self.dims[k] - 1)
        })
    }

    /// Squared distance from `p` to the nearest triangle. `seen` is scratch (one stamp per
    /// triangle) and `stamp` a value not yet used in it.
    pub(crate) fn nearest_squared(&self, p: Vec3, seen: &mut [u32], stamp: u32) -> f64 {
        let c = self.cell_of(p);
        let mut best = f64::INFINITY;
        let max_r = *self.dims.iter().max().unwrap_or(&1);
        for r in 0..=max_r {
            // Cells at Chebyshev distance r from c.
            let lo = c.map(|x| x as isize - r as isize);
            let hi = c.map(|x| x as isize + r as isize);
            for z in lo[2].max(0)..=hi[2].min(self.dims[2] as isize - 1) {
                for y in lo[1].max(0)..=hi[1].min(self.dims[1] as isize - 1) {
                    let on_shell_zy = z == lo[2] || z == hi[2] || y == lo[1] || y == hi[1];
                    let step = if on_shell_zy { 1 } else { (2 * r).max(1) };
                    let mut x = lo[0];
                    while x <= hi[0] {
                        if x >= 0 && x < self.dims[0] as isize {
                            let cell = self.index([x as usize, y as usize, z as usize]);
                            let range = self.start[cell] as usize..self.start[cell + 1] as usize;
                            for &t in &self.items[range] {
                                if seen[t as usize] != stamp {
                                    seen[t as usize] = stamp;
                                    let [a, b, cc] = self.triangles[t as usize];
                                    best = best.min(point_triangle_distance_squared(p, a, b, cc));
                                }
                            }
                        }
                        x += step as isize;
                    }
                }
            }
            // Unvisited triangles lie in cells at least r + 1 away: at distance >= r · cell.
            let reach = r as f64 * self.cell;
            if best <= reach * reach {
                break;
            }
        }
        best
    }

    pub(crate) fn triangle_count(&self) -> usize {
        self.triangles.len()
    }
}

fn tri_box(t: &[Vec3; 3]) -> (Vec3, Vec3) {
    let lo = [0, 1, 2].map(|k| t[0][k].min(t[1][k]).min(t[2][k]));
    let hi = [0, 1, 2].map(|k| t[0][k].max(t[1][k]).max(t[2][k]));
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_query_equals_brute_force() {
        // Triangles scattered on a wavy sheet, queries above, below and far outside it.
        let mut triangles = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let h = |x: f64, y: f64| 0.3 * (x * 0.7).sin() * (y * 0.5).cos();
                let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
                triangles.push([
                    [x, y, h(x, y)],
                    [x + 0.5, y, h(x + 0.5, y)],
                    [x, y + 0.4, 0.1],
                ]);
            }
        }
        let queries: Vec<Vec3> = (0..200)
            .map(|k| {
                let t = k as f64;
                [
                    12.0 * (0.13 * t).sin().abs(),
                    11.0 * (0.29 * t).cos().abs(),
                    2.0 * (0.7 * t).sin(),
                ]
            })
            .chain([[30.0, -5.0, 4.0], [-3.0, -3.0, -3.0]])
            .collect();
        let grid = TriangleGrid::new(triangles.clone(), &queries);
        let mut seen = vec![0u32; grid.triangle_count()];
        for (k, &p) in queries.iter().enumerate() {
            let brute = triangles
                .iter()
                .map(|[a, b, c]| point_triangle_distance_squared(p, *a, *b, *c))
                .fold(f64::INFINITY, f64::min);
            let fast = grid.nearest_squared(p, &mut seen, k as u32 + 1);
            assert!(
                (fast - brute).abs() <= 1e-12 * (1.0 + brute),
                "{fast} vs {brute} at {p:?}"
            );
        }
    }
}
