//! The hierarchy: levels 0..=L of a template (graph, positions, rescaled Laplacian) and the
//! pooling operators between consecutive levels.

use crate::error::HierarchyError;
use crate::laplacian::{LambdaMax, adjacency, normalized_laplacian, rescaled_laplacian};
use crate::pooling::{DepoolMode, Pooler, PoolingOp};
use crate::sampling;
use crate::sparse::CsrMatrix;
use mesh_io::{Face, Point, TriMesh};
use qem_simplify::{SimplifyConfig, Target, simplify};
use serde::{Deserialize, Serialize};

/// Settings of [`Hierarchy::build`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HierarchyConfig {
    pub pooler: Pooler,
    /// Number of pooling steps: 1 for 'CCPC', 2 for 'CCPCCPC'.
    pub levels: usize,
    /// Fraction of vertices kept per pooling step, in (0, 1] (the paper: 0.5).
    pub ratio: f64,
    pub lambda_max: LambdaMax,
    /// De-pooling of mean poolers (ignored by `sampling`, which up-samples, and `none`).
    pub depool: DepoolMode,
}

impl Default for HierarchyConfig {
    fn default() -> Self {
        Self {
            pooler: Pooler::Ours,
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
    /// Builds the hierarchy of `template`: each pooling step simplifies the previous level to
    /// `ratio` of its vertices (λ by pooler) and builds that step's operators.
    ///
    /// Errors: an invalid template or configuration, or a simplification that fails.
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
            let n = fine.vertex_count;
            let Some(lambda) = config.pooler.lambda() else {
                pooling.push(PoolingOp::identity(n));
                levels.push(fine.clone());
                continue;
            };
            let fine_mesh = fine.mesh();
            let simplified = simplify(
                &fine_mesh,
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
                kind => PoolingOp::from_clusters(kind, &simplified.cluster_of, m, config.depool)?,
            };
            pooling.push(op);
            levels.push(Level::of(&simplified.coarse, config.lambda_max));
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
        }
        Ok(())
    }
}
