//! The columns: every network variant the reproduction trains, one entry of [`COLUMNS`] each
//! (the paper's ablation columns, its structures, and the other auto-encoders).

use crate::reproduce::paper::AblationColumn;
use meshvae::{ConvKind, ModelConfig, Network, Pooler, Structure};

/// Which of the paper's tables a column belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Group {
    /// The ablation table (pooling and convolution variants, structure `CCPC`).
    Ablation,
    /// The structure table (our pooling, other layer strings).
    Structure,
    /// The other auto-encoders (`table:ERMS`, and SpiralNet++), each as its authors define it.
    Framework,
}

/// One network variant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Column {
    /// Folder and JSON name.
    pub id: &'static str,
    /// Row label in our tables.
    pub label: &'static str,
    pub group: Group,
    /// The paper's ablation column it reproduces (`None`: not in the paper's table).
    pub paper: Option<AblationColumn>,
    pub structure: &'static str,
    pub conv: ConvKind,
    pub pool: Pooler,
    /// The auto-encoder: ours (shaped by the three fields above) or another one, fixed as its
    /// authors define it (the three fields are then unused).
    pub net: Network,
}

impl Column {
    /// Our method: in both tables, the reference every other column is compared with.
    pub fn is_ours(&self) -> bool {
        self.id == OURS
    }

    /// The model configuration: the paper's defaults with this column's structure, convolution
    /// and pooling, or the other network's own.
    pub fn model(&self) -> Result<ModelConfig, meshvae::VaeError> {
        if !self.net.is_ours() {
            return Ok(ModelConfig::for_network(self.net));
        }
        Ok(ModelConfig {
            structure: self.structure.parse::<Structure>()?,
            conv: self.conv,
            pool: self.pool,
            ..ModelConfig::default()
        })
    }
}

/// The id of our method's column.
pub const OURS: &str = "ours";

/// Every column, in table order. "Only Spatial Conv." and "Only Spectral Conv." have no
/// pooling (the paper: "'Only Spectral Conv.' also means 'No Pooling'"; the authors' code's
/// no-pooling network).
pub const COLUMNS: &[Column] = &[
    Column {
        id: "spatial",
        label: "Only Spatial Conv. (no pooling)",
        group: Group::Ablation,
        paper: Some(AblationColumn::SpatialConv),
        structure: "CCPC",
        conv: ConvKind::Spatial,
        pool: Pooler::None,
        net: Network::Ours,
    },
    Column {
        id: "no-pool",
        label: "Only Spectral Conv. (no pooling)",
        group: Group::Ablation,
        paper: Some(AblationColumn::SpectralConv),
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::None,
        net: Network::Ours,
    },
    Column {
        id: "qem",
        label: "classical QEM, mean pooling",
        group: Group::Ablation,
        paper: Some(AblationColumn::ClassicalQem),
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Qem,
        net: Network::Ours,
    },
    Column {
        id: "remesh",
        label: "uniform remeshing, mean pooling",
        group: Group::Ablation,
        paper: Some(AblationColumn::UniformSimp),
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Remesh,
        net: Network::Ours,
    },
    Column {
        id: "graph",
        label: "graph pooling (Shen et al. 2018)",
        group: Group::Ablation,
        paper: Some(AblationColumn::GraphPooling),
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Graph,
        net: Network::Ours,
    },
    Column {
        id: "sampling",
        label: "CoMA mesh sampling",
        group: Group::Ablation,
        paper: Some(AblationColumn::MeshSampling),
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Sampling,
        net: Network::Ours,
    },
    Column {
        id: "max",
        label: "modified QEM, max pooling",
        group: Group::Ablation,
        paper: None,
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Max,
        net: Network::Ours,
    },
    Column {
        id: OURS,
        label: "**ours** (modified QEM, mean pooling)",
        group: Group::Ablation,
        paper: Some(AblationColumn::Ours),
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Mean,
        net: Network::Ours,
    },
    Column {
        id: "cpcpc",
        label: "`CPCPC` (ours, two poolings)",
        group: Group::Structure,
        paper: None,
        structure: "CPCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Mean,
        net: Network::Ours,
    },
    Column {
        id: "ccpccpc",
        label: "`CCPCCPC` (ours, two poolings)",
        group: Group::Structure,
        paper: None,
        structure: "CCPCCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Mean,
        net: Network::Ours,
    },
    Column {
        id: "tan2018",
        label: "Tan et al. 2018 (mesh VAE, fully connected)",
        group: Group::Framework,
        paper: None,
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::None,
        net: Network::Tan2018,
    },
    Column {
        id: "coma",
        label: "Ranjan et al. 2018 (CoMA)",
        group: Group::Framework,
        paper: None,
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Sampling,
        net: Network::Coma,
    },
    Column {
        id: "spiralnet",
        label: "Gong et al. 2019 (SpiralNet++)",
        group: Group::Framework,
        paper: None,
        structure: "CCPC",
        conv: ConvKind::Spectral,
        pool: Pooler::Sampling,
        net: Network::SpiralNet,
    },
];

/// The column named `id`.
pub fn column(id: &str) -> Option<&'static Column> {
    COLUMNS.iter().find(|c| c.id == id)
}
