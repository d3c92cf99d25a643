//! Fine vertex → coarse vertex for a remeshing, which keeps no correspondence of its own: each
//! fine vertex joins the coarse vertex nearest to it along the fine mesh's edges.
//!
//! Every coarse vertex seeds one distinct fine vertex of its own component: its nearest (by
//! straight-line distance), or, when an earlier coarse vertex took that one, the nearest
//! untaken vertex to it along the fine edges (which stays on the same side of a thin part).
//! A multi-source Dijkstra over the fine edges (Euclidean lengths) then labels every fine
//! vertex with its geodesically nearest seed. A seed sits at distance 0 and nothing beats 0,
//! so no cluster is empty; each cluster is a shortest-path tree, so it is connected on the fine
//! mesh. A fine component no coarse vertex lies on (and a vertex no face uses) joins the coarse
//! vertex nearest to any of its vertices, flooded from that vertex: the result stays a
//! partition.

use super::surface::NONE;
use crate::error::{Result, SimplifyError};
use crate::geometry::{Vec3, distance};
use crate::nearest::NearestGrid;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// The fine mesh as the clustering sees it.
pub(crate) struct Fine<'a> {
    pub positions: &'a [Vec3],
    pub faces: &'a [[u32; 3]],
    /// Fine vertex → component, [`NONE`] for a vertex no face uses.
    pub component_of: &'a [u32],
}

/// The coarse vertex of each fine vertex. `coarse_component[k]` is the fine component coarse
/// vertex k lies on. Errors when a component holds more coarse vertices than fine ones (no
/// distinct seeds).
pub(crate) fn geodesic_clusters(
    fine: &Fine,
    coarse: &[Vec3],
    coarse_component: &[u32],
) -> Result<Vec<u32>> {
    let n = fine.positions.len();
    if coarse.is_empty() {
        return Err(SimplifyError::InvalidArgument {
            argument: "coarse",
            message: "no coarse vertex to cluster around".into(),
        });
    }
    let adjacency = adjacency(n, fine.faces, fine.positions);
    let seeds = seeds(fine, &adjacency, coarse, coarse_component)?;
    let mut label = vec![NONE; n];
    let mut dist = vec![f64::INFINITY; n];
    let mut heap = BinaryHeap::new();
    for (k, &s) in seeds.iter().enumerate() {
        label[s as usize] = k as u32;
        dist[s as usize] = 0.0;
        heap.push(Reverse((0u64, s)));
    }
    flood(&adjacency, &mut label, &mut dist, &mut heap);

    // What no seed reached: join the nearest coarse vertex, component by component.
    if label.contains(&NONE) {
        let points = coarse.iter().map(|&p| [p; 3]).collect();
        let grid = NearestGrid::new(points, (0..coarse.len() as u32).collect());
        // Per component: (squared distance, fine vertex, coarse vertex) of its nearest pair.
        let mut best: Vec<Option<(f64, u32, u32)>> = vec![None; count(fine.component_of)];
        let group = |v: usize| match fine.component_of[v] {
            NONE => None,
            c => Some(c as usize),
        };
        for (v, l) in label.iter_mut().enumerate() {
            if *l != NONE {
                continue;
            }
            let Some(near) = grid.closest(fine.positions[v], |_| true) else {
                continue;
            };
            let candidate = (near.distance_squared, v as u32, near.id);
            match group(v) {
                // A lone vertex is its own component: it joins its nearest at once.
                None => *l = near.id,
                Some(c) => {
                    if best[c].is_none_or(|b| (candidate.0, candidate.1) < (b.0, b.1)) {
                        best[c] = Some(candidate);
                    }
                }
            }
        }
        for &(_, v, k) in best.iter().flatten() {
            label[v as usize] = k;
            dist[v as usize] = 0.0;
            heap.push(Reverse((0, v)));
        }
        flood(&adjacency, &mut label, &mut dist, &mut heap);
    }
    Ok(label)
}

/// One distinct fine vertex per coarse vertex, in coarse order: the nearest fine vertex of the
/// coarse vertex's component, or, if taken, the untaken one nearest to that along the edges.
fn seeds(
    fine: &Fine,
    adjacency: &Adjacency,
    coarse: &[Vec3],
    coarse_component: &[u32],
) -> Result<Vec<u32>> {
    let components = count(fine.component_of);
    let mut members: Vec<(Vec<[Vec3; 3]>, Vec<u32>)> = vec![(Vec::new(), Vec::new()); components];
    for (v, &c) in fine.component_of.iter().enumerate() {
        if c != NONE {
            members[c as usize].0.push([fine.positions[v]; 3]);
            members[c as usize].1.push(v as u32);
        }
    }
    // Room for a distinct seed each: checked first, so every search below succeeds.
    let mut crowd = vec![0usize; components];
    for k in 0..coarse.len() {
        let c = coarse_component.get(k).copied().unwrap_or(NONE);
        match crowd.get_mut(c as usize) {
            Some(count) => *count += 1,
            None => {
                return Err(SimplifyError::ComponentTooSmall {
                    component: c as usize,
                    fine: 0,
                    coarse: 1,
                });
            }
        }
    }
    if let Some(c) = (0..components).find(|&c| crowd[c] > members[c].1.len()) {
        return Err(SimplifyError::ComponentTooSmall {
            component: c,
            fine: members[c].1.len(),
            coarse: crowd[c],
        });
    }
    let grids: Vec<NearestGrid> = members
        .into_iter()
        .map(|(points, ids)| NearestGrid::new(points, ids))
        .collect();
    let mut taken = vec![false; fine.positions.len()];
    let mut search = Search::new(fine.positions.len());
    let mut seeds = Vec::with_capacity(coarse.len());
    for (k, &p) in coarse.iter().enumerate() {
        let c = coarse_component[k] as usize;
        let Some(nearest) = grids[c].closest(p, |_| true) else {
            continue;
        };
        let seed = if taken[nearest.id as usize] {
            search.nearest_untaken(adjacency, nearest.id, &taken)
        } else {
            Some(nearest.id)
        };
        // The count check above leaves an untaken vertex in every component searched.
        let Some(seed) = seed else {
            return Err(SimplifyError::ComponentTooSmall {
                component: c,
                fine: grids[c].len(),
                coarse: crowd[c],
            });
        };
        taken[seed as usize] = true;
        seeds.push(seed);
    }
    Ok(seeds)
}

/// A Dijkstra over the fine edges that stops at the first untaken vertex, with its distances
/// kept between searches (only what a search touched is reset).
struct Search {
    dist: Vec<f64>,
    touched: Vec<u32>,
    heap: BinaryHeap<Reverse<(u64, u32)>>,
}

impl Search {
    fn new(n: usize) -> Self {
        Self {
            dist: vec![f64::INFINITY; n],
            touched: Vec::new(),
            heap: BinaryHeap::new(),
        }
    }

    /// The untaken vertex nearest to `from` along the edges (ties by index), if any.
    fn nearest_untaken(&mut self, adjacency: &Adjacency, from: u32, taken: &[bool]) -> Option<u32> {
        self.dist[from as usize] = 0.0;
        self.touched.push(from);
        self.heap.push(Reverse((0, from)));
        let mut found = None;
        while let Some(Reverse((key, v))) = self.heap.pop() {
            let d = f64::from_bits(key);
            if d > self.dist[v as usize] {
                continue;
            }
            if !taken[v as usize] {
                found = Some(v);
                break;
            }
            for &(w, length) in adjacency.around(v) {
                let nd = d + length;
                if nd < self.dist[w as usize] {
                    if self.dist[w as usize].is_infinite() {
                        self.touched.push(w);
                    }
                    self.dist[w as usize] = nd;
                    self.heap.push(Reverse((nd.to_bits(), w)));
                }
            }
        }
        for &v in &self.touched {
            self.dist[v as usize] = f64::INFINITY;
        }
        self.touched.clear();
        self.heap.clear();
        found
    }
}

/// How many components `component_of` labels.
fn count(component_of: &[u32]) -> usize {
    component_of
        .iter()
        .filter(|&&c| c != NONE)
        .map(|&c| c as usize + 1)
        .max()
        .unwrap_or(0)
}

/// Neighbours of each vertex with the edge lengths (CSR, each edge both ways, ascending).
struct Adjacency {
    start: Vec<u32>,
    to: Vec<(u32, f64)>,
}

impl Adjacency {
    fn around(&self, v: u32) -> &[(u32, f64)] {
        &self.to[self.start[v as usize] as usize..self.start[v as usize + 1] as usize]
    }
}

fn adjacency(n: usize, faces: &[[u32; 3]], positions: &[Vec3]) -> Adjacency {
    let mut pairs: Vec<(u32, u32)> = faces
        .iter()
        .flat_map(|f| [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])])
        .flat_map(|(a, b)| [(a, b), (b, a)])
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    let mut start = vec![0u32; n + 1];
    for &(a, _) in &pairs {
        start[a as usize + 1] += 1;
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    let to = pairs
        .iter()
        .map(|&(a, b)| (b, distance(positions[a as usize], positions[b as usize])))
        .collect();
    Adjacency { start, to }
}

/// Dijkstra from what `heap` holds: a vertex takes the label of the vertex it is first reached
/// from by a strictly shorter path. Keys are the distances' bits (non-negative floats order as
/// their bits), ties broken by vertex index: the same input labels the same way every time.
fn flood(
    adjacency: &Adjacency,
    label: &mut [u32],
    dist: &mut [f64],
    heap: &mut BinaryHeap<Reverse<(u64, u32)>>,
) {
    while let Some(Reverse((key, v))) = heap.pop() {
        let d = f64::from_bits(key);
        if d > dist[v as usize] {
            continue;
        }
        for &(w, length) in adjacency.around(v) {
            let nd = d + length;
            if nd < dist[w as usize] {
                dist[w as usize] = nd;
                label[w as usize] = label[v as usize];
                heap.push(Reverse((nd.to_bits(), w)));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::to_f64;

    fn fine_of(mesh: &mesh_io::TriMesh) -> (Vec<Vec3>, Vec<u32>) {
        let positions = mesh.positions.iter().map(|&p| to_f64(p)).collect();
        let mut component = vec![NONE; mesh.vertex_count()];
        for f in &mesh.faces {
            for &v in f {
                component[v as usize] = 0;
            }
        }
        (positions, component)
    }

    /// Brute force: all geodesic distances along the edges (Floyd–Warshall).
    fn all_pairs(positions: &[Vec3], faces: &[[u32; 3]]) -> Vec<Vec<f64>> {
        let n = positions.len();
        let mut d = vec![vec![f64::INFINITY; n]; n];
        for (v, row) in d.iter_mut().enumerate() {
            row[v] = 0.0;
        }
        for f in faces {
            for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
                let l = distance(positions[a as usize], positions[b as usize]);
                d[a as usize][b as usize] = l;
                d[b as usize][a as usize] = l;
            }
        }
        for k in 0..n {
            for i in 0..n {
                for j in 0..n {
                    let via = d[i][k] + d[k][j];
                    if via < d[i][j] {
                        d[i][j] = via;
                    }
                }
            }
        }
        d
    }

    #[test]
    fn each_vertex_joins_its_geodesically_nearest_seed() {
        let mesh = crate::shapes::bumpy_grid(9, 8);
        let (positions, component) = fine_of(&mesh);
        let fine = Fine {
            positions: &positions,
            faces: &mesh.faces,
            component_of: &component,
        };
        // Coarse points near some fine vertices, two of them nearest the same one.
        let coarse: Vec<Vec3> = [3usize, 40, 41, 70, 20]
            .iter()
            .map(|&v| positions[v])
            .chain([[positions[40][0] + 0.01, positions[40][1], positions[40][2]]])
            .collect();
        let label = geodesic_clusters(&fine, &coarse, &[0; 6]).expect("clusters");
        let mut sizes = vec![0; coarse.len()];
        for &l in &label {
            sizes[l as usize] += 1;
        }
        assert!(sizes.iter().all(|&s| s > 0), "{sizes:?}");
        let adjacency = adjacency(positions.len(), &mesh.faces, &positions);
        let seeds = seeds(&fine, &adjacency, &coarse, &[0; 6]).unwrap();
        let mut distinct = seeds.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), seeds.len(), "distinct seeds");
        assert_eq!(&seeds[..5], &[3, 40, 41, 70, 20]);
        let d = all_pairs(&positions, &mesh.faces);
        // The sixth coarse vertex found 40 taken: it seeds the untaken vertex nearest to 40
        // along the edges.
        let untaken = (0..positions.len() as u32).filter(|v| ![3, 40, 41, 70, 20].contains(v));
        let expected = untaken
            .min_by(|&x, &y| d[40][x as usize].total_cmp(&d[40][y as usize]))
            .unwrap();
        assert_eq!(seeds[5], expected);
        // Each vertex's own seed is (one of) the geodesically nearest.
        for v in 0..positions.len() {
            let nearest = seeds
                .iter()
                .map(|&s| d[s as usize][v])
                .fold(f64::INFINITY, f64::min);
            let own = d[seeds[label[v] as usize] as usize][v];
            assert!(
                (own - nearest).abs() < 1e-12,
                "vertex {v}: {own} vs {nearest}"
            );
        }
    }

    #[test]
    fn unseeded_components_and_lone_vertices_join_the_nearest() {
        // Two grids side by side, and an unused vertex far off; coarse vertices on grid 0 only.
        let a = crate::shapes::bumpy_grid(4, 4);
        let mut positions: Vec<Vec3> = a.positions.iter().map(|&p| to_f64(p)).collect();
        let mut faces = a.faces.clone();
        let shift = positions.len() as u32;
        positions.extend(
            a.positions
                .iter()
                .map(|&p| [p[0] as f64 + 3.0, p[1] as f64, 0.0]),
        );
        faces.extend(a.faces.iter().map(|f| f.map(|v| v + shift)));
        positions.push([-5.0, 0.0, 0.0]);
        let mut component = vec![0; 16];
        component.extend([1; 16]);
        component.push(NONE);
        let fine = Fine {
            positions: &positions,
            faces: &faces,
            component_of: &component,
        };
        let coarse = vec![[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
        let label = geodesic_clusters(&fine, &coarse, &[0, 0]).unwrap();
        assert!(!label.contains(&NONE));
        // Grid 1 is nearest to coarse vertex 1 (at x = 1), the lone vertex to coarse vertex 0.
        assert!(label[16..32].iter().all(|&l| l == 1));
        assert_eq!(label[32], 0);
        assert!(label[..16].contains(&0) && label[..16].contains(&1));
        // More coarse vertices on a component than it has fine ones: a typed error.
        let crowded = vec![[0.0; 3]; 17];
        let err = geodesic_clusters(&fine, &crowded, &[0; 17]).unwrap_err();
        assert!(matches!(
            err,
            SimplifyError::ComponentTooSmall {
                component: 0,
                fine: 16,
                coarse: 17
            }
        ));
    }
}
