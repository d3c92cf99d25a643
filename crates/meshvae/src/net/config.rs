//! [`ModelConfig`]: every choice that shapes the network (saved as JSON with a model), and the
//! layer plan ([`ConvSpec`]) that both the model and the parameter count are built from.

use crate::error::{Result, VaeError};
use crate::net::network::Network;
use crate::net::structure::{Layer, Structure};
use mesh_hierarchy::{HierarchyConfig, Pooler};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Channels of the per-vertex ACAP feature (log-rotation 3 + stretch 6): the network's input and
/// output width.
pub const FEATURE_CHANNELS: usize = 9;

/// The graph convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ConvKind {
    /// Chebyshev spectral convolution of order K (the paper).
    #[default]
    Spectral,
    /// Self plus neighbour-mean convolution (the paper's "Only Spatial Conv." ablation).
    Spatial,
}

macro_rules! names {
    ($ty:ty, $what:literal, $($variant:ident => $name:literal),+) => {
        impl fmt::Display for $ty {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(match self { $(Self::$variant => $name),+ })
            }
        }

        impl FromStr for $ty {
            type Err = VaeError;

            fn from_str(s: &str) -> Result<Self> {
                match s.to_ascii_lowercase().as_str() {
                    $($name => Ok(Self::$variant),)+
                    _ => Err(VaeError::argument(
                        $what,
                        format!("{s:?} is not one of {}", [$($name),+].join(", ")),
                    )),
                }
            }
        }
    };
}

names!(ConvKind, "conv", Spectral => "spectral", Spatial => "spatial");

/// The network's configuration. `Default` is the paper's network as the authors' code runs it
/// (its released TensorFlow code), except `last_encoder_linear`, which follows the
/// paper's text.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelConfig {
    /// Which auto-encoder: ours (built from the fields below) or one of the others, which are
    /// fixed as their authors define them and read only `latent` ([`Network`]). Absent from the
    /// JSON of our network's models.
    #[serde(default, skip_serializing_if = "Network::is_ours")]
    pub net: Network,
    /// Encoder layers, e.g. `CCPC`; the decoder mirrors them.
    pub structure: Structure,
    pub conv: ConvKind,
    /// The pooling between levels (the paper's ablation), and the hierarchy's pooler.
    pub pool: Pooler,
    /// Chebyshev terms (orders 0 … K−1) of a spectral convolution; unused by spatial ones.
    pub k: usize,
    /// Size of the latent vector z.
    pub latent: usize,
    /// Width of every hidden convolution (the authors: 9, as the input).
    pub channels: usize,
    /// Batch norm after every convolution except the last encoder one and the output one.
    pub batch_norm: bool,
    /// No activation on the last encoder convolution (the paper's text); `false` = tanh (the
    /// authors' code).
    pub last_encoder_linear: bool,
    /// Each decoder convolution is the adjoint of its mirror encoder convolution (the paper's
    /// text) instead of having its own weights (the authors' code).
    pub tie_decoder_convs: bool,
    /// Standard deviation of the normal initialisation of every weight matrix.
    pub init_std: f64,
    /// The class labels of a conditional VAE, in one-hot order (empty: unconditional). Absent
    /// from the JSON of an unconditional model, so older model folders read as unconditional.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub labels: Vec<String>,
}

impl Default for ModelConfig {
    fn default() -> Self {
        Self {
            net: Network::Ours,
            structure: Structure::default(),
            conv: ConvKind::Spectral,
            pool: Pooler::Mean,
            k: 3,
            latent: 128,
            channels: FEATURE_CHANNELS,
            batch_norm: true,
            last_encoder_linear: true,
            tie_decoder_convs: false,
            init_std: 0.02,
            labels: Vec::new(),
        }
    }
}

/// One convolution of the plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvSpec {
    /// Index of the encoder convolution (a decoder convolution carries its mirror's index).
    pub index: usize,
    /// Hierarchy level it runs on (0 = template).
    pub level: usize,
    pub c_in: usize,
    pub c_out: usize,
    /// Followed by batch norm.
    pub batch_norm: bool,
    /// Followed by tanh (otherwise linear).
    pub tanh: bool,
}

impl ModelConfig {
    /// The configuration of `net`: ours as [`Self::default`], the others with their authors'
    /// latent size.
    pub fn for_network(net: Network) -> Self {
        Self {
            net,
            latent: net.default_latent(),
            ..Self::default()
        }
    }

    /// Number of pooling steps = number of P in the structure. With `pool = none` the hierarchy
    /// still has that many (identity) steps, every level being the template.
    pub fn pool_levels(&self) -> usize {
        self.net
            .pool_levels()
            .unwrap_or_else(|| self.structure.pools())
    }

    /// `HierarchyConfig::default()` with this configuration's pooler and level count (for the
    /// position networks, CoMA's sampling, keeping 1/4 of the vertices at each level).
    pub fn hierarchy_config(&self) -> HierarchyConfig {
        let (pooler, ratio) = match self.net.position_net() {
            Some(net) => (Pooler::Sampling, 1.0 / net.factor as f64),
            None if self.net == Network::Tan2018 => (Pooler::None, 0.5),
            None => (self.pool, HierarchyConfig::default().ratio),
        };
        HierarchyConfig {
            pooler,
            levels: self.pool_levels(),
            ratio,
            ..HierarchyConfig::default()
        }
    }

    /// The pooler of the model's hierarchy (ours: `pool`; the others' own).
    pub fn pooler(&self) -> Pooler {
        self.hierarchy_config().pooler
    }

    /// Whether the model is a conditional VAE (it has labels).
    pub fn is_conditional(&self) -> bool {
        !self.labels.is_empty()
    }

    /// This configuration made conditional on the distinct values of `mesh_labels` (one label
    /// per mesh), in order of first appearance.
    pub fn conditional_on(self, mesh_labels: &[String]) -> Self {
        let mut labels: Vec<String> = Vec::new();
        for l in mesh_labels {
            if !labels.contains(l) {
                labels.push(l.clone());
            }
        }
        Self { labels, ..self }
    }

    /// Checks the sizes: K, latent, channels ≥ 1, a finite, non-negative `init_std`, and
    /// distinct, non-empty labels.
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("k", self.k),
            ("latent", self.latent),
            ("channels", self.channels),
        ];
        for (arg, value) in positive {
            if value == 0 {
                return Err(VaeError::argument(arg, "must be at least 1"));
            }
        }
        if !(self.init_std.is_finite() && self.init_std >= 0.0) {
            return Err(VaeError::argument(
                "init_std",
                format!("{} is not a finite non-negative number", self.init_std),
            ));
        }
        if !self.net.is_ours() && self.is_conditional() {
            return Err(VaeError::argument(
                "labels",
                format!(
                    "a conditional model is ours only; {} takes no labels",
                    self.net
                ),
            ));
        }
        for (i, l) in self.labels.iter().enumerate() {
            if l.trim().is_empty() || self.labels[..i].contains(l) {
                return Err(VaeError::argument(
                    "labels",
                    format!("{l:?} is empty or repeated in {:?}", self.labels),
                ));
            }
        }
        Ok(())
    }

    /// The encoder's convolutions in order: the first maps the 9 feature channels to
    /// `channels`, every other one keeps `channels`.
    pub fn encoder_convs(&self) -> Vec<ConvSpec> {
        let total = self.structure.convs();
        let mut level = 0;
        let mut convs = Vec::with_capacity(total);
        for layer in self.structure.layers() {
            match layer {
                Layer::Pool => level += 1,
                Layer::Conv => {
                    let index = convs.len();
                    let last = index + 1 == total;
                    convs.push(ConvSpec {
                        index,
                        level,
                        c_in: if index == 0 {
                            FEATURE_CHANNELS
                        } else {
                            self.channels
                        },
                        c_out: self.channels,
                        batch_norm: self.batch_norm && !last,
                        tanh: !(last && self.last_encoder_linear),
                    });
                }
            }
        }
        convs
    }

    /// The decoder's convolutions in the order they run: the mirrors of the encoder's, in
    /// reverse, with input and output widths swapped (so the last one, the output convolution,
    /// maps `channels` to 9). All end in tanh; all but the output one have batch norm.
    pub fn decoder_convs(&self) -> Vec<ConvSpec> {
        self.encoder_convs()
            .into_iter()
            .rev()
            .map(|e| ConvSpec {
                index: e.index,
                level: e.level,
                c_in: e.c_out,
                c_out: e.c_in,
                batch_norm: self.batch_norm && e.index != 0,
                tanh: true,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_json_round_trip() {
        let c = ModelConfig::default();
        assert_eq!((c.k, c.latent, c.channels, c.init_std), (3, 128, 9, 0.02));
        assert_eq!(c.pool, Pooler::Mean);
        assert_eq!(c.pool_levels(), 1);
        let json = serde_json::to_string(&c).unwrap();
        assert!(json.contains("\"structure\":\"CCPC\""), "{json}");
        assert!(json.contains("\"pool\":\"mean\"") && json.contains("\"conv\":\"spectral\""));
        assert_eq!(serde_json::from_str::<ModelConfig>(&json).unwrap(), c);
    }

    #[test]
    fn names_parse_like_the_cli() {
        for p in Pooler::ALL {
            assert_eq!(p.to_string().parse::<Pooler>().unwrap(), p);
        }
        assert_eq!("QEM".parse::<Pooler>().unwrap(), Pooler::Qem);
        assert_eq!("spatial".parse::<ConvKind>().unwrap(), ConvKind::Spatial);
        let err = "avg".parse::<Pooler>().unwrap_err().to_string();
        assert!(err.contains("pooler") && err.contains("\"avg\""), "{err}");
        // The names of the command line, of config.json and of hierarchy files; `ours` is the
        // hierarchy's old name of `mean`.
        let names: Vec<String> = Pooler::ALL.iter().map(|p| p.to_string()).collect();
        assert_eq!(
            names,
            ["mean", "max", "qem", "sampling", "none", "graph", "remesh"]
        );
        assert_eq!("ours".parse::<Pooler>().unwrap(), Pooler::Mean);
        assert_eq!(
            serde_json::from_str::<Pooler>("\"ours\"").unwrap(),
            Pooler::Mean
        );
        assert_eq!(serde_json::to_string(&Pooler::Mean).unwrap(), "\"mean\"");
        let c = ModelConfig {
            pool: Pooler::Graph,
            ..Default::default()
        };
        assert_eq!(c.hierarchy_config().pooler, Pooler::Graph);
        assert_eq!("graph".parse::<Pooler>().unwrap(), Pooler::Graph);
        assert_eq!("Remesh".parse::<Pooler>().unwrap(), Pooler::Remesh);
        let json = serde_json::to_string(&Pooler::Graph).unwrap();
        assert_eq!(json, "\"graph\"");
        assert_eq!(
            serde_json::from_str::<Pooler>("\"remesh\"").unwrap(),
            Pooler::Remesh
        );
        let err = "kcnet".parse::<Pooler>().unwrap_err().to_string();
        assert!(err.contains("graph") && err.contains("remesh"), "{err}");
    }

    #[test]
    fn the_plan_mirrors_the_encoder() {
        let c = ModelConfig {
            structure: "CPCC".parse().unwrap(),
            channels: 16,
            ..Default::default()
        };
        let enc = c.encoder_convs();
        let levels: Vec<_> = enc.iter().map(|s| (s.level, s.c_in, s.c_out)).collect();
        assert_eq!(levels, [(0, 9, 16), (1, 16, 16), (1, 16, 16)]);
        assert_eq!(
            enc.iter().map(|s| s.batch_norm).collect::<Vec<_>>(),
            [true, true, false]
        );
        assert_eq!(
            enc.iter().map(|s| s.tanh).collect::<Vec<_>>(),
            [true, true, false]
        );
        let dec = c.decoder_convs();
        let plan: Vec<_> = dec
            .iter()
            .map(|s| (s.index, s.level, s.c_in, s.c_out))
            .collect();
        assert_eq!(plan, [(2, 1, 16, 16), (1, 1, 16, 16), (0, 0, 16, 9)]);
        assert_eq!(
            dec.iter().map(|s| s.batch_norm).collect::<Vec<_>>(),
            [true, true, false]
        );
        assert!(dec.iter().all(|s| s.tanh));
        let authors = ModelConfig {
            last_encoder_linear: false,
            batch_norm: false,
            ..c
        };
        assert!(
            authors
                .encoder_convs()
                .iter()
                .all(|s| s.tanh && !s.batch_norm)
        );
        assert!(
            ModelConfig {
                k: 0,
                ..Default::default()
            }
            .validate()
            .is_err()
        );
        assert!(
            ModelConfig {
                init_std: f64::NAN,
                ..Default::default()
            }
            .validate()
            .is_err()
        );
        assert!(ModelConfig::default().validate().is_ok());
    }

    #[test]
    fn labels_are_optional_in_json_and_ordered_by_first_appearance() {
        // An unconditional model's JSON has no "labels" key, as before labels existed.
        let plain = ModelConfig::default();
        let json = serde_json::to_string(&plain).unwrap();
        assert!(!json.contains("labels"), "{json}");
        let cond = plain
            .clone()
            .conditional_on(&["pose", "gallop", "pose"].map(String::from));
        assert_eq!(cond.labels, ["pose", "gallop"]);
        assert!(cond.is_conditional() && !plain.is_conditional());
        let json = serde_json::to_string(&cond).unwrap();
        assert!(json.contains("\"labels\":[\"pose\",\"gallop\"]"), "{json}");
        assert_eq!(serde_json::from_str::<ModelConfig>(&json).unwrap(), cond);
        let repeated = ModelConfig {
            labels: vec!["a".into(), "a".into()],
            ..Default::default()
        };
        let err = repeated.validate().unwrap_err().to_string();
        assert!(err.contains("labels") && err.contains("repeated"), "{err}");
    }
}
