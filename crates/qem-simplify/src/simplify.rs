//! The simplifier: configuration, the contraction loop, and its result.

use crate::collapse::State;
use crate::connectivity::Connectivity;
use crate::error::{Result, SimplifyError};
use crate::geometry::{Vec3, scale, sub, to_f64};
use crate::heap::EdgeQueue;
use crate::manifold::topology;
use mesh_io::{Face, Point, TriMesh};

/// The paper's weight of the edge-length term, for lengths measured on the mesh scaled to a
/// unit bounding-box diagonal.
pub const DEFAULT_LAMBDA: f64 = 0.001;

/// How many vertices the coarse mesh keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    /// A fraction in (0, 1] of the input's vertices, rounded up.
    Ratio(f64),
    /// An exact count, between 1 and the input's vertex count.
    Vertices(usize),
}

impl Default for Target {
    /// Half of the vertices, rounded up: the paper contracts half per level.
    fn default() -> Self {
        Self::Ratio(0.5)
    }
}

impl Target {
    /// The vertex count this target asks of a mesh with `vertex_count` vertices.
    pub fn resolve(self, vertex_count: usize) -> Result<usize> {
        match self {
            Self::Ratio(r) if r.is_finite() && r > 0.0 && r <= 1.0 => {
                Ok(((vertex_count as f64 * r).ceil() as usize).clamp(1, vertex_count))
            }
            Self::Ratio(r) => Err(SimplifyError::InvalidArgument {
                argument: "ratio",
                message: format!("{r} is not in (0, 1]"),
            }),
            Self::Vertices(n) if (1..=vertex_count).contains(&n) => Ok(n),
            Self::Vertices(n) => Err(SimplifyError::InvalidArgument {
                argument: "target",
                message: format!("{n} vertices is not between 1 and the input's {vertex_count}"),
            }),
        }
    }
}

/// Settings of [`simplify`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimplifyConfig {
    pub target: Target,
    /// Weight λ of the edge-length term of Eq. 1, for lengths in units of the input's
    /// bounding-box diagonal (so one value fits every mesh); 0 gives classical QEM.
    pub lambda: f64,
}

impl Default for SimplifyConfig {
    fn default() -> Self {
        Self {
            target: Target::default(),
            lambda: DEFAULT_LAMBDA,
        }
    }
}

/// The coarse mesh and how the fine vertices map onto it.
///
/// Pooling needs only the map ([`Simplified::cluster_of`]); the coarse positions (the quadric
/// optima of the contractions) matter for the coarse mesh's own connectivity and Laplacian and
/// for the geometric error.
#[derive(Debug, Clone, PartialEq)]
pub struct Simplified {
    /// The coarse mesh. Coarse vertex k is the k-th surviving fine vertex in ascending index.
    pub coarse: TriMesh,
    /// Fine vertex → the coarse vertex whose cluster it belongs to (that of its last surviving
    /// ancestor). Every cluster is connected on the fine mesh.
    pub cluster_of: Vec<u32>,
    /// Coarse vertex → the fine vertex that survived as it (ascending).
    pub survivors: Vec<u32>,
    /// Coarse face → the fine face it descends from (its corners relabelled).
    pub face_origin: Vec<u32>,
}

impl Simplified {
    /// The fine vertices of each coarse vertex's cluster, in ascending order.
    pub fn clusters(&self) -> Vec<Vec<u32>> {
        let mut clusters = vec![Vec::new(); self.survivors.len()];
        for (fine, &coarse) in self.cluster_of.iter().enumerate() {
            clusters[coarse as usize].push(fine as u32);
        }
        clusters
    }

    /// How many fine vertices each coarse vertex stands for.
    pub fn cluster_sizes(&self) -> Vec<usize> {
        let mut sizes = vec![0; self.survivors.len()];
        for &c in &self.cluster_of {
            sizes[c as usize] += 1;
        }
        sizes
    }
}

/// Simplifies `mesh` by quadric edge collapse with the paper's edge-length term (Eq. 1) down to
/// exactly the target vertex count, keeping a 2-manifold of the same topology with no flipped or
/// degenerate face. Deterministic: the same input gives the same output on every run.
///
/// Errors: an invalid mesh or configuration, a non-manifold input, or a target that no sequence
/// of valid contractions reaches from this input.
pub fn simplify(mesh: &TriMesh, config: &SimplifyConfig) -> Result<Simplified> {
    mesh.validate(std::path::Path::new("<mesh>"))?;
    if !(config.lambda.is_finite() && config.lambda >= 0.0) {
        return Err(SimplifyError::InvalidArgument {
            argument: "lambda",
            message: format!("{} is not a finite number >= 0", config.lambda),
        });
    }
    let n = mesh.vertex_count();
    let target = config.target.resolve(n)?;
    let mut topology = topology(n, &mesh.faces).map_err(SimplifyError::NonManifold)?;
    let (center, diagonal) = frame(&mesh.positions);
    if diagonal <= 0.0 {
        return Err(SimplifyError::ZeroExtent { vertices: n });
    }
    let normalised = mesh
        .positions
        .iter()
        .map(|&p| scale(sub(to_f64(p), center), 1.0 / diagonal))
        .collect();
    let boundary = std::mem::take(&mut topology.boundary);
    let connectivity = Connectivity::from_topology(&mesh.faces, topology);
    let mut state = State::new(
        normalised,
        &mesh.faces,
        &boundary,
        connectivity,
        config.lambda,
    );
    let parent = contract_to(&mut state, target)?;
    Ok(assemble(&state, &parent, center, diagonal))
}

/// Bounding-box centre and diagonal length.
fn frame(points: &[Point]) -> (Vec3, f64) {
    match mesh_io::bbox(points) {
        Some((lo, hi)) => {
            let center = [0, 1, 2].map(|k| 0.5 * (f64::from(lo[k]) + f64::from(hi[k])));
            (center, mesh_io::bbox_diagonal(points))
        }
        None => ([0.0; 3], 0.0),
    }
}

/// Runs contractions, cheapest valid first, until `target` vertices remain. Returns each
/// vertex's parent: itself for survivors, else the (lower-indexed) vertex it merged into.
fn contract_to(state: &mut State, target: usize) -> Result<Vec<u32>> {
    let n = state.positions.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    state.place_all();
    // Invariant: every queued edge's key is at most its true cost. Costs that may drop are
    // pushed at once; costs that can only grow (a length term whose farthest neighbour stayed
    // put) are left as they are and settled when they reach the top. So the edge at the top
    // with key = true cost is the cheapest of all: the greedy order is exact.
    let edge_count = state.mesh.edge_id_count() as u32;
    let mut queue = EdgeQueue::from_costs((0..edge_count).map(|e| state.cost_of(e)));
    let mut remaining = n;
    let (mut ring, mut around, mut dead) = (Vec::new(), Vec::new(), Vec::new());
    while remaining > target {
        let Some((edge, key)) = queue.peek() else {
            return Err(SimplifyError::TargetUnreachable {
                target,
                reached: remaining,
            });
        };
        // The likely next tops (if this one is raised or taken): where their ends' edges are.
        for next in queue.next_tops() {
            state.prefetch_ends(next);
        }
        let cost = state.settle(edge);
        state.prefetch_incident(edge);
        debug_assert!(
            cost.total_cmp(&key).is_ge(),
            "a queued key above its true cost"
        );
        if cost.total_cmp(&key).is_gt() {
            queue.raise_top(cost);
            continue;
        }
        queue.pop();
        let [keep, remove] = state.mesh.edge(edge);
        let p = state.placed(edge);
        if !state.is_valid(keep, remove, p) {
            // Out of the queue until a contraction nearby re-costs it.
            continue;
        }
        dead.clear();
        state.contract(keep, remove, p, &mut dead);
        for &e in &dead {
            queue.prefetch(e);
        }
        for &e in &dead {
            queue.remove(e);
        }
        parent[remove as usize] = keep;
        remaining -= 1;
        // The edges at `keep` need a new v̄; the other edges of its neighbours may have a
        // shorter length term (then re-measured now) or a longer one (settled at the top).
        // Either may have become valid again: all go (back) into the queue.
        ring.clear();
        prefetch_spokes(state, &queue, keep);
        for i in 0..state.mesh.edges_around(keep).len() {
            let spoke = state.mesh.edges_around(keep)[i];
            ring.push(spoke.to);
            let cost = state.replace(spoke.edge, keep, spoke.to, remove);
            queue.set(spoke.edge, cost);
        }
        // The edges of the ring vertices, but those at `keep` (re-placed above).
        around.clear();
        for &w in &ring {
            for &spoke in state.mesh.edges_around(w) {
                if spoke.to != keep {
                    around.push(spoke.edge);
                    state.prefetch_farthest(spoke.edge);
                    queue.prefetch_slot(spoke.edge);
                }
            }
        }
        for &e in &around {
            if state.length_may_drop(e, keep, remove) {
                state.prefetch_placed(e);
                queue.prefetch(e);
            }
        }
        // An edge between two ring vertices is seen twice; the second visit finds it queued
        // with `keep` as its farthest neighbour, and repeating the lowering changes nothing.
        for &e in &around {
            if state.length_may_drop(e, keep, remove) {
                let cost = state.lower_length(e, keep);
                queue.set(e, cost);
            } else if !queue.contains(e) {
                queue.set(e, state.cost_of(e));
            }
        }
        if let Some((top, _)) = queue.peek() {
            state.prefetch_top(top);
            for next in queue.next_tops() {
                state.prefetch_top(next);
            }
        }
    }
    Ok(parent)
}

/// Asks for what re-placing the edges at `keep` reads, in stages, each reading what the
/// previous one asked for: records of the edges and their other ends, then those ends' edge
/// lists and heap entries, then the positions of their neighbours (the length term's).
fn prefetch_spokes(state: &State, queue: &EdgeQueue, keep: u32) {
    for &spoke in state.mesh.edges_around(keep) {
        state.prefetch_edge(spoke.edge, spoke.to);
        queue.prefetch_slot(spoke.edge);
    }
    for &spoke in state.mesh.edges_around(keep) {
        state.mesh.prefetch_edges_around(spoke.to);
        queue.prefetch(spoke.edge);
    }
    for &spoke in state.mesh.edges_around(keep) {
        state.prefetch_neighbours(spoke.to);
    }
}

/// Builds the coarse mesh (survivors in ascending order, live faces in fine order) and the map.
fn assemble(state: &State, parent: &[u32], center: Vec3, diagonal: f64) -> Simplified {
    let n = parent.len();
    let mut coarse_index = vec![u32::MAX; n];
    let mut survivors = Vec::new();
    for v in 0..n {
        if parent[v] as usize == v {
            coarse_index[v] = survivors.len() as u32;
            survivors.push(v as u32);
        }
    }
    // parent[v] < v for every merged vertex, so one ascending pass resolves whole chains.
    let mut cluster_of = vec![0u32; n];
    for v in 0..n {
        cluster_of[v] = if parent[v] as usize == v {
            coarse_index[v]
        } else {
            cluster_of[parent[v] as usize]
        };
    }
    let positions = survivors
        .iter()
        .map(|&v| {
            let p = state.positions[v as usize];
            [0, 1, 2].map(|k| (p[k] * diagonal + center[k]) as f32)
        })
        .collect();
    let (face_origin, faces): (Vec<u32>, Vec<Face>) = state
        .mesh
        .live_faces()
        .map(|(i, f)| (i as u32, f.map(|v| coarse_index[v as usize])))
        .unzip();
    Simplified {
        coarse: TriMesh { positions, faces },
        cluster_of,
        survivors,
        face_origin,
    }
}
