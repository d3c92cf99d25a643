//! Isotropic remeshing of a template to a vertex count, with a cluster map for pooling: the
//! "uniform remeshing" column of the paper's Table 3. The method is described on [`remesh`].

mod cluster;
mod editable;
mod passes;
mod repair;
mod surface;

pub use passes::Smoothing;
pub use surface::flipped_faces_on_surface;

use crate::error::{Result, SimplifyError};
use crate::geometry::{area_vector, norm, to_f64};
use crate::manifold::topology;
use crate::simplify::Target;
use editable::Editable;
use mesh_io::TriMesh;
use surface::Surface;

/// Settings of [`remesh`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RemeshConfig {
    /// The coarse mesh's vertex count, met exactly.
    pub target: Target,
    /// Rounds of split / collapse / flip / relax-and-project, each followed by a re-calibration
    /// of the target edge length (Botsch & Kobbelt use 5 to 10). At least 1.
    pub iterations: usize,
    /// Rounds of flip / relax-and-project after the count is made exact.
    pub final_rounds: usize,
    /// Neighbour weights of the tangential relaxation.
    pub smoothing: Smoothing,
}

impl Default for RemeshConfig {
    fn default() -> Self {
        Self {
            target: Target::Ratio(0.5),
            iterations: 8,
            final_rounds: 3,
            smoothing: Smoothing::Area,
        }
    }
}

/// The remeshed template and the map from its vertices to the coarse ones.
#[derive(Debug, Clone, PartialEq)]
pub struct Remeshed {
    /// The remeshed template: a 2-manifold of the input's topology, on its surface.
    pub coarse: TriMesh,
    /// Fine (template) vertex → coarse vertex: the geodesically nearest along the fine edges.
    /// Every coarse index is used, and every cluster is connected on the fine mesh.
    pub cluster_of: Vec<u32>,
}

impl Remeshed {
    /// How many fine vertices each coarse vertex stands for.
    pub fn cluster_sizes(&self) -> Vec<usize> {
        let mut sizes = vec![0; self.coarse.vertex_count()];
        for &c in &self.cluster_of {
            if let Some(s) = sizes.get_mut(c as usize) {
                *s += 1;
            }
        }
        sizes
    }
}

/// Remeshes `mesh` (a 2-manifold, closed or with boundary) isotropically to exactly the target
/// vertex count, keeping its topology, and maps every fine vertex to a coarse one.
/// Deterministic: the same input gives the same output on any number of threads.
///
/// ## The method
/// Botsch & Kobbelt 2004 ("A remeshing approach to multiresolution modeling"): rounds of, at a
/// target edge length L,
/// 1. split every edge longer than 4/3·L at its midpoint (a boundary edge's midpoint stays on
///    the boundary);
/// 2. collapse edges shorter than 4/5·L, shortest first, into their midpoint (into the boundary
///    end when one end alone is on the boundary; two boundary vertices only along a boundary
///    edge), never creating an edge longer than 4/3·L, never breaking the link condition (the
///    surface stays a 2-manifold of the same topology), never turning over or squashing a face;
/// 3. flip inner edges where that brings valences closer to 6 (4 on the boundary);
/// 4. tangential relaxation (area-weighted by default, see [`Smoothing`]), then projection onto
///    the closest point of the *original* template, through a uniform grid: on the vertex's
///    own connected component, on faces facing the way the vertex does (which keeps it on its
///    side of a part thinner than an edge), boundary vertices on their own boundary loop (a
///    polyline). A vertex whose move would turn over or squash a face stays put.
///
/// **Count.** L starts at √(2·area / (√3·target)) (equilateral faces, two faces per vertex).
/// After each round, L ← L·√(reached / target), the step clamped to ±10 % because the count
/// lags L by a round or two. After [`RemeshConfig::iterations`] rounds the count is within a
/// few percent; then the shortest edges are collapsed (or the longest split) until it is
/// *exactly* the target, and [`RemeshConfig::final_rounds`] rounds of flips and relaxation
/// even the result out without changing it.
///
/// **Flips.** The steps above compare a face with its own previous state, so on thin parts a
/// face can turn over by small steps. A last pass compares every face with the template (see
/// [`flipped_faces_on_surface`]) and fixes the flipped ones locally: an edge flip, a corner
/// moved, or an edge collapsed and the longest edge elsewhere split (the count stays exact),
/// each only when it lowers the number of flipped faces around.
///
/// **Clusters.** The remeshing keeps no correspondence; [`Remeshed::cluster_of`] sends each
/// fine vertex to the coarse vertex nearest to it *geodesically along the fine mesh's edges*:
/// a multi-source Dijkstra (Euclidean edge lengths) seeded at one distinct fine vertex per
/// coarse vertex: the nearest to it on its own component, or, when an earlier coarse vertex
/// took that one, the untaken vertex nearest to that one along the fine edges. A seed is at
/// distance 0, so no cluster is empty; each cluster is a shortest-path tree, so it is
/// connected on the fine mesh. A fine component without coarse vertices (and a vertex no face
/// uses) joins the coarse vertex nearest to any of its vertices.
///
/// ```
/// use qem_simplify::{RemeshConfig, Target, remesh};
/// # fn main() -> Result<(), qem_simplify::SimplifyError> {
/// let sphere = qem_simplify::shapes::icosphere(3); // 642 vertices
/// let config = RemeshConfig { target: Target::Vertices(200), ..RemeshConfig::default() };
/// let r = remesh(&sphere, &config)?;
/// assert_eq!(r.coarse.vertex_count(), 200);
/// assert_eq!(r.cluster_of.len(), 642);
/// assert!(r.cluster_sizes().iter().all(|&size| size > 0));
/// # Ok(()) }
/// ```
///
/// Errors: an invalid mesh (empty, non-finite, indices out of range), a non-manifold one, one
/// with zero extent or area, a target outside 1..=vertex count, `iterations` = 0, a target no
/// valid collapse reaches, or a template component holding fewer vertices than the coarse
/// vertices on it.
pub fn remesh(mesh: &TriMesh, config: &RemeshConfig) -> Result<Remeshed> {
    mesh.validate(std::path::Path::new("<mesh>"))?;
    if config.iterations == 0 {
        return Err(SimplifyError::InvalidArgument {
            argument: "iterations",
            message: "remeshing needs at least one round".into(),
        });
    }
    let n = mesh.vertex_count();
    let target = config.target.resolve(n)?;
    let topology = topology(n, &mesh.faces).map_err(SimplifyError::NonManifold)?;
    if mesh.bbox_diagonal() <= 0.0 {
        return Err(SimplifyError::ZeroExtent { vertices: n });
    }
    let positions: Vec<_> = mesh.positions.iter().map(|&p| to_f64(p)).collect();
    let area: f64 = mesh
        .faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|v| positions[v as usize]);
            norm(area_vector(a, b, c)) / 2.0
        })
        .sum();
    if area <= 0.0 {
        return Err(SimplifyError::ZeroArea {
            faces: mesh.face_count(),
        });
    }
    let boundary: Vec<[u32; 2]> = topology
        .boundary
        .iter()
        .map(|&e| topology.edges[e as usize])
        .collect();
    let surface = Surface::new(mesh, &boundary);
    let mut m = Editable::new(
        positions.clone(),
        &mesh.faces,
        surface.loop_of.clone(),
        surface.component_of.clone(),
    );

    let mut length = (2.0 * area / (3f64.sqrt() * target as f64)).sqrt();
    for _ in 0..config.iterations {
        round(&mut m, &surface, length, config.smoothing);
        // The count scales as 1 / L², but lags behind L by a round or two: a gentle step.
        let ratio = m.vertex_count() as f64 / target as f64;
        length *= ratio.sqrt().clamp(0.9, 1.1);
    }
    passes::reach_count(&mut m, target, 4.0 / 3.0 * length)?;
    passes::project_all(&mut m, &surface);
    for _ in 0..config.final_rounds {
        passes::equalize_valences(&mut m);
        passes::relax_and_project(&mut m, &surface, config.smoothing);
    }
    repair::repair_flips(&mut m, &surface);
    let (coarse_positions, faces, coarse_component) = m.compact();
    let cluster_of = cluster::geodesic_clusters(
        &cluster::Fine {
            positions: &positions,
            faces: &mesh.faces,
            component_of: &surface.component_of,
        },
        &coarse_positions,
        &coarse_component,
    )?;
    let coarse = TriMesh {
        positions: coarse_positions
            .iter()
            .map(|p| p.map(|x| x as f32))
            .collect(),
        faces,
    };
    Ok(Remeshed { coarse, cluster_of })
}

/// One round of Botsch & Kobbelt's loop at target edge length `length`.
fn round(m: &mut Editable, surface: &Surface, length: f64, smoothing: Smoothing) {
    let (low, high) = (0.8 * length, 4.0 / 3.0 * length);
    passes::split_long(m, high);
    passes::collapse_short(m, low, high);
    passes::equalize_valences(m);
    passes::relax_and_project(m, surface, smoothing);
}
