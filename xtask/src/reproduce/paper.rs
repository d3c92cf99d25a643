//! The paper's numbers (Yuan et al. 2020, *Mesh Variational Autoencoders with Edge Contraction
//! Pooling*), typed in once so that every table of `docs/results.md` quotes the same figures.
//!
//! The paper calls all of them "RMS reconstruction errors for unseen data"; the authors' shipped
//! evaluation (`show_error.m`) computes a rigidly aligned *mean per-vertex distance*, which is
//! the closest of our measures to them.

/// The columns of the paper's ablation table (`table:different_sim`), in its order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AblationColumn {
    SpatialConv,
    SpectralConv,
    ClassicalQem,
    UniformSimp,
    GraphPooling,
    MeshSampling,
    Ours,
}

impl AblationColumn {
    /// Every column, in the paper's order.
    pub const ALL: [AblationColumn; 7] = [
        Self::SpatialConv,
        Self::SpectralConv,
        Self::ClassicalQem,
        Self::UniformSimp,
        Self::GraphPooling,
        Self::MeshSampling,
        Self::Ours,
    ];

    /// The column's heading as the paper writes it.
    pub fn heading(self) -> &'static str {
        match self {
            Self::SpatialConv => "Only Spatial Conv.",
            Self::SpectralConv => "Only Spectral Conv. (no pooling)",
            Self::ClassicalQem => "classical QEM (Garland 1997)",
            Self::UniformSimp => "Uniform Simp. (remeshing)",
            Self::GraphPooling => "Graph Pooling",
            Self::MeshSampling => "Mesh Sampling (CoMA)",
            Self::Ours => "Our Method",
        }
    }

    fn index(self) -> usize {
        Self::ALL.iter().position(|&c| c == self).unwrap_or(0)
    }
}

/// One row of the ablation table: a data set and its seven errors in [`AblationColumn::ALL`]
/// order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AblationRow {
    pub dataset: &'static str,
    pub values: [f64; 7],
}

impl AblationRow {
    pub fn get(&self, column: AblationColumn) -> f64 {
        self.values[column.index()]
    }
}

/// `table:different_sim`.
pub const ABLATION: [AblationRow; 4] = [
    AblationRow {
        dataset: "SCAPE",
        values: [0.1086, 0.0825, 0.0898, 0.0813, 0.0824, 0.0831, 0.0763],
    },
    AblationRow {
        dataset: "Swing",
        values: [0.0359, 0.0282, 0.0284, 0.0281, 0.0292, 0.0298, 0.0268],
    },
    AblationRow {
        dataset: "Fat",
        values: [0.0362, 0.0267, 0.0285, 0.0305, 0.0253, 0.0289, 0.0249],
    },
    AblationRow {
        dataset: "Hand",
        values: [0.0300, 0.0284, 0.0271, 0.0280, 0.0306, 0.0278, 0.0260],
    },
];

/// The improvements of ours the paper's text claims ("lower by an average of …"), in percent
/// (negative = ours lower).
pub const CLAIMS: [(AblationColumn, f64); 4] = [
    (AblationColumn::SpectralConv, -8.36),
    (AblationColumn::ClassicalQem, -9.17),
    (AblationColumn::GraphPooling, -8.06),
    (AblationColumn::MeshSampling, -9.64),
];

/// Mean over the ablation table's rows of (ours − other) / other, in percent: how the paper's
/// averages are computed (it reproduces the claims against graph pooling and mesh sampling to
/// the printed digits; those against no pooling and classical QEM come out at −6.92 % and
/// −9.34 %, so the text's figures for them do not follow from the table as printed).
pub fn table_mean_change(other: AblationColumn) -> f64 {
    let sum: f64 = ABLATION
        .iter()
        .map(|row| relative_change(row.get(AblationColumn::Ours), row.get(other)))
        .sum();
    sum / ABLATION.len() as f64
}

/// (ours − other) / other in percent.
pub fn relative_change(ours: f64, other: f64) -> f64 {
    (ours - other) / other * 100.0
}

/// `table:structure_compare` (SCAPE only): `CPCPC`, `CCPCCPC`, ours (`CCPC`).
pub const STRUCTURES: (&str, [(&str, f64); 3]) = (
    "SCAPE",
    [("CPCPC", 0.0942), ("CCPCCPC", 0.0863), ("CCPC", 0.0763)],
);

/// One row of `table:ERMS` (other auto-encoders): vertices, Tan et al. 2018, Gao et al. 2018,
/// Ranjan et al. 2018 (CoMA), ours; `None` = out of memory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameworkRow {
    pub dataset: &'static str,
    pub vertices: usize,
    pub tan: Option<f64>,
    pub gao: f64,
    pub ranjan: f64,
    pub ours: f64,
}

/// `table:ERMS`.
pub const FRAMEWORKS: [FrameworkRow; 7] = [
    FrameworkRow {
        dataset: "SCAPE",
        vertices: 12500,
        tan: None,
        gao: 0.1086,
        ranjan: 0.1095,
        ours: 0.0763,
    },
    FrameworkRow {
        dataset: "Swing",
        vertices: 9971,
        tan: None,
        gao: 0.0359,
        ranjan: 0.0557,
        ours: 0.0268,
    },
    FrameworkRow {
        dataset: "Fat",
        vertices: 6890,
        tan: Some(0.0308),
        gao: 0.0362,
        ranjan: 0.0324,
        ours: 0.0249,
    },
    FrameworkRow {
        dataset: "Hand",
        vertices: 3573,
        tan: Some(0.0362),
        gao: 0.0300,
        ranjan: 0.0632,
        ours: 0.0260,
    },
    FrameworkRow {
        dataset: "Face",
        vertices: 11849,
        tan: None,
        gao: 1.0619,
        ranjan: 1.1479,
        ours: 0.7257,
    },
    FrameworkRow {
        dataset: "Horse",
        vertices: 8431,
        tan: None,
        gao: 0.0128,
        ranjan: 0.0510,
        ours: 0.0119,
    },
    FrameworkRow {
        dataset: "Camel",
        vertices: 11063,
        tan: None,
        gao: 0.0134,
        ranjan: 0.0265,
        ours: 0.0115,
    },
];

/// A row of `table:parameters`: data set, vertices, the coarse vertex count our formula needs
/// to give the paper's figure, Tan et al.'s count, ours.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamRow {
    pub dataset: &'static str,
    pub vertices: usize,
    pub coarse: usize,
    pub tan: usize,
    pub ours: usize,
}

/// `table:parameters`.
pub const PARAMS: [ParamRow; 2] = [
    ParamRow {
        dataset: "Fat",
        vertices: 6890,
        coarse: 3446,
        tan: 129_745_920,
        ours: 7_941_042,
    },
    ParamRow {
        dataset: "Hand",
        vertices: 3573,
        coarse: 1787,
        tan: 68_610_048,
        ours: 4_118_706,
    },
];

/// The paper's data set that one of ours matches (same subject and template): horse-gallop is
/// the paper's Horse, samba is a sequence of the Swing capture's subject and template.
pub fn matching_row(dataset: &str) -> Option<&'static str> {
    match dataset {
        "horse-gallop" => Some("Horse"),
        "samba" => Some("Swing"),
        _ => None,
    }
}

/// How our data set stands to its [`matching_row`]: what a reader must know before setting the
/// two figures side by side.
pub fn matching_note(dataset: &str) -> &'static str {
    match dataset {
        "horse-gallop" => "the same animation",
        "samba" => "the same subject and template, another sequence",
        _ => "no matching data set",
    }
}

/// Our copy of horse-gallop is Sumner and Popović's original files scaled by this factor about
/// the origin (measured on every vertex of the 48 frames: the least-squares factor is the same
/// for each, and no vertex is further than 8e-8 from it; the faces and the vertex order are the
/// same). Our horse-poses copy has the same factor.
pub const HORSE_COPY_SCALE: f64 = 1.676_881_5;

/// How many units of our copy of `dataset` one unit of the paper's matching data set is, where
/// it is known. Errors in mesh units follow the scale (the features do not change under a uniform
/// scale and the reconstructions scale with the rest mesh; deform-features tests it), and the
/// authors' pipeline measures its errors on reconstructed meshes in the files' own units with no
/// rescaling step; so, assuming the authors used the files as distributed, the paper's absolute
/// errors are comparable with ours after multiplying them by this factor. Samba is at its
/// original scale (metres, as captured), so it needs none.
pub fn copy_scale(dataset: &str) -> Option<f64> {
    match dataset {
        "horse-gallop" => Some(HORSE_COPY_SCALE),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_reproduces_two_claims_and_not_the_other_two() {
        let close = |a: f64, b: f64| (a - b).abs() < 0.005;
        for (column, claim) in CLAIMS {
            let recomputed = table_mean_change(column);
            let expect_match = matches!(
                column,
                AblationColumn::GraphPooling | AblationColumn::MeshSampling
            );
            assert_eq!(
                close(recomputed, claim),
                expect_match,
                "{column:?}: table {recomputed:.3} % vs claim {claim} %"
            );
        }
        assert!((table_mean_change(AblationColumn::SpectralConv) + 6.92).abs() < 0.005);
        assert!((table_mean_change(AblationColumn::ClassicalQem) + 9.34).abs() < 0.005);
    }

    #[test]
    fn ours_is_the_lowest_of_every_paper_row() {
        for row in ABLATION {
            let ours = row.get(AblationColumn::Ours);
            assert!(row.values.iter().all(|&v| v >= ours), "{}", row.dataset);
        }
        let horse = FRAMEWORKS.iter().find(|r| r.dataset == "Horse").unwrap();
        assert_eq!((horse.vertices, horse.ours), (8431, 0.0119));
        assert_eq!(matching_row("samba"), Some("Swing"));
        assert_eq!(matching_row("synthetic"), None);
    }
}
