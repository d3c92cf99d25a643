//! The hierarchy: levels 0..=L of a template (graph, positions, rescaled Laplacian) and the
//! pooling operators between consecutive levels.

use crate::error::HierarchyError;
use crate::laplacian::{LambdaMax, adjacency, normalized_laplacian, rescaled_laplacian};
use crate::pooling::{DepoolMode, Pooler, PoolingOp};
use crate::sampling;
use mesh_io::{Face, Point, TriMesh};
use qem_simplify::{RemeshConfig, SimplifyConfig, Target, remesh, simplify};
use serde::{Deserialize, Serialize};
use sparse_csr::CsrMatrix;

/// Settings of [`Hierarchy::build`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HierarchyConfig {
    pub pooler: Pooler,
    /// Number of pooling steps: 1 for 'CCPC', 2 for 'CCPCCPC'.
    pub levels: usize,
    /// Fraction of vertices kept per pooling step, in (0, 1] (the paper: 0.5).
    pub ratio: f64,
    pub lambda_max: LambdaMax,
    /// De-pooling of mean poolers (`ours`, `qem`, `max`, `remesh`; ignored by `sampling`, which
    /// up-samples, `graph`, which averages over overlapping neighbourhoods, and `none`).
    pub depool: DepoolMode,
}

impl Default for HierarchyConfig {
    fn default() -> Self {
        Self {
            pooler: Pooler::Mean,
            levels: 1,
            ratio: 0.5,
            lambda_max: LambdaMax::Two,
            depool: DepoolMode::Copy,
        }
    }
}

/// One level of the hierarchy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Level {
    pub vertex_count: usize,
    pub faces: Vec<Face>,
    /// The template's positions (level 0) or the simplifier's coarse positions.
    pub positions: Vec<Point>,
    /// The rescaled Laplacian L̃ = 2L/λmax − I of this level's own connectivity.
    pub laplacian: CsrMatrix,
}

impl Level {
    /// A level of `mesh`, with its rescaled Laplacian.
    pub fn of(mesh: &TriMesh, lambda_max: LambdaMax) -> Self {
        let l = normalized_laplacian(&adjacency(mesh.vertex_count(), &mesh.faces));
        Self {
            vertex_count: mesh.vertex_count(),
            faces: mesh.faces.clone(),
            positions: mesh.positions.clone(),
            laplacian: rescaled_laplacian(&l, lambda_max),
        }
    }

    fn mesh(&self) -> TriMesh {
        TriMesh {
            positions: self.positions.clone(),
            faces: self.faces.clone(),
        }
    }
}

/// Levels 0..=L and the L pooling operators between them (`pooling[i]`: level i → i + 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Hierarchy {
    pub levels: Vec<Level>,
    pub pooling: Vec<PoolingOp>,
    pub config: HierarchyConfig,
}

impl Hierarchy {
    /// Builds the hierarchy of `template`: each pooling step simplifies (λ by pooler) or, for
    /// `remesh`, remeshes the previous level to `ratio` of its vertices and builds that step's
    /// operators.
    ///
    /// Errors: an invalid template or configuration, or a simplification or remeshing that
    /// fails.
    pub fn build(template: &TriMesh, config: &HierarchyConfig) -> Result<Self, HierarchyError> {
        template.validate(std::path::Path::new("<template>"))?;
        if !(config.ratio.is_finite() && config.ratio > 0.0 && config.ratio <= 1.0) {
            return Err(HierarchyError::InvalidArgument {
                argument: "ratio",
                message: format!("{} is not in (0, 1]", config.ratio),
            });
        }
        if let LambdaMax::PowerIteration(0) = config.lambda_max {
            return Err(HierarchyError::InvalidArgument {
                argument: "lambda_max",
                message: "power iteration needs at least one iteration".into(),
            });
        }
        let mut levels = vec![Level::of(template, config.lambda_max)];
        let mut pooling = Vec::with_capacity(config.levels);
        for _ in 0..config.levels {
            let fine = &levels[levels.len() - 1];
            let (op, coarse) = match config.pooler {
                Pooler::None => (PoolingOp::identity(fine.vertex_count), fine.clone()),
                Pooler::Remesh => remesh_step(&fine.mesh(), config)?,
                _ => simplify_step(&fine.mesh(), config)?,
            };
            pooling.push(op);
            levels.push(coarse);
        }
        Ok(Self {
            levels,
            pooling,
            config: *config,
        })
    }

    /// Vertex counts of levels 0..=L.
    pub fn vertex_counts(&self) -> Vec<usize> {
        self.levels.iter().map(|l| l.vertex_count).collect()
    }

    /// Checks that every operator's shape agrees with the levels it joins and that faces and
    /// clusters are in range; `Err` holds what is wrong.
    pub fn check_shapes(&self) -> Result<(), String> {
        if self.levels.is_empty() || self.pooling.len() + 1 != self.levels.len() {
            return Err(format!(
                "{} levels for {} pooling operators",
                self.levels.len(),
                self.pooling.len()
            ));
        }
        for (i, level) in self.levels.iter().enumerate() {
            let n = level.vertex_count;
            if level.positions.len() != n {
                return Err(format!(
                    "level {i}: {} positions for {n} vertices",
                    level.positions.len()
                ));
            }
            if level.faces.iter().flatten().any(|&v| v as usize >= n) {
                return Err(format!("level {i}: a face index beyond {n} vertices"));
            }
            if level.positions.iter().flatten().any(|x| !x.is_finite()) {
                return Err(format!("level {i}: a non-finite position"));
            }
            if (level.laplacian.rows(), level.laplacian.cols()) != (n, n) {
                return Err(format!("level {i}: Laplacian is not {n}x{n}"));
            }
        }
        for (i, op) in self.pooling.iter().enumerate() {
            let (n, m) = (self.levels[i].vertex_count, self.levels[i + 1].vertex_count);
            if (op.pool.rows(), op.pool.cols()) != (m, n) {
                return Err(format!("pooling {i}: pool is not {m}x{n}"));
            }
            if (op.depool.rows(), op.depool.cols()) != (n, m) {
                return Err(format!("pooling {i}: depool is not {n}x{m}"));
            }
            if let Some(clusters) = &op.clusters
                && (clusters.len() != m || clusters.iter().flatten().any(|&v| v as usize >= n))
            {
                return Err(format!(
                    "pooling {i}: clusters do not match {m} coarse of {n}"
                ));
            }
            // A max over an empty neighbourhood, or a fine vertex in none, would silently
            // give zeros.
            if op.kind == Pooler::Graph {
                let mut covered = vec![false; n];
                op.pool
                    .indices()
                    .iter()
                    .for_each(|&u| covered[u as usize] = true);
                let empty = (0..m).any(|c| op.pool.row(c).0.is_empty());
                if empty || covered.contains(&false) {
                    return Err(format!(
                        "pooling {i}: a graph neighbourhood is empty or a fine vertex is in none"
                    ));
                }
            }
        }
        Ok(())
    }
}

/// One pooling step of a simplification-based pooler: the simplified level and its operators.
fn simplify_step(
    fine_mesh: &TriMesh,
    config: &HierarchyConfig,
) -> Result<(PoolingOp, Level), HierarchyError> {
    let lambda = config
        .pooler
        .lambda()
        .ok_or(HierarchyError::InvalidArgument {
            argument: "pooler",
            message: format!("{} does not simplify", config.pooler),
        })?;
    let n = fine_mesh.vertex_count();
    let simplified = simplify(
        fine_mesh,
        &SimplifyConfig {
            target: Target::Ratio(config.ratio),
            lambda,
        },
    )?;
    let m = simplified.coarse.vertex_count();
    let op = match config.pooler {
        Pooler::Sampling => PoolingOp {
            kind: Pooler::Sampling,
            pool: sampling::selection(&simplified.survivors, n)?,
            depool: sampling::upsampling(
                &fine_mesh.positions,
                &simplified.cluster_of,
                &simplified.coarse.positions,
                &simplified.coarse.faces,
            )?,
            clusters: None,
        },
        Pooler::Graph => PoolingOp::graph(
            &fine_mesh.faces,
            &simplified.survivors,
            &simplified.cluster_of,
        )?,
        kind => PoolingOp::from_clusters(kind, &simplified.cluster_of, m, config.depool)?,
    };
    Ok((op, Level::of(&simplified.coarse, config.lambda_max)))
}

/// One pooling step of uniform remeshing: the remeshed level and mean pooling over the fine
/// vertices' clusters (de-pooling as `config.depool`).
fn remesh_step(
    fine_mesh: &TriMesh,
    config: &HierarchyConfig,
) -> Result<(PoolingOp, Level), HierarchyError> {
    let remeshed = remesh(
        fine_mesh,
        &RemeshConfig {
            target: Target::Ratio(config.ratio),
            ..Default::default()
        },
    )?;
    let m = remeshed.coarse.vertex_count();
    let op = PoolingOp::from_clusters(Pooler::Remesh, &remeshed.cluster_of, m, config.depool)?;
    Ok((op, Level::of(&remeshed.coarse, config.lambda_max)))
}
