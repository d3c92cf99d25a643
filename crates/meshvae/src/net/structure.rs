//! [`Structure`]: the encoder's layer string, e.g. `CCPC` = conv, conv, pool, conv (the paper's
//! default). The decoder mirrors it: the same layers in reverse order, each pool a de-pool.

use crate::error::VaeError;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// One encoder layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Layer {
    /// A graph convolution on the current level.
    Conv,
    /// Pooling to the next, coarser level (de-pooling back in the decoder).
    Pool,
}

/// A non-empty sequence of convolutions and poolings with at least one convolution.
///
/// Parsed case-insensitively from `C`/`P` strings; serialised as its upper-case string.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Structure(Vec<Layer>);

impl Structure {
    /// The encoder's layers, in order.
    pub fn layers(&self) -> &[Layer] {
        &self.0
    }

    /// Number of convolutions in the encoder (the decoder has as many).
    pub fn convs(&self) -> usize {
        self.0.iter().filter(|&&l| l == Layer::Conv).count()
    }

    /// Number of poolings, i.e. of hierarchy levels below the template.
    pub fn pools(&self) -> usize {
        self.0.iter().filter(|&&l| l == Layer::Pool).count()
    }
}

impl Default for Structure {
    /// `CCPC`, the paper's network.
    fn default() -> Self {
        Self(vec![Layer::Conv, Layer::Conv, Layer::Pool, Layer::Conv])
    }
}

impl FromStr for Structure {
    type Err = VaeError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let layers = s
            .chars()
            .enumerate()
            .map(|(i, ch)| match ch.to_ascii_uppercase() {
                'C' => Ok(Layer::Conv),
                'P' => Ok(Layer::Pool),
                _ => Err(VaeError::argument(
                    "structure",
                    format!(
                        "{s:?}: character {ch:?} at position {i} is neither C (conv) nor P (pool)"
                    ),
                )),
            })
            .collect::<Result<Vec<_>, _>>()?;
        if !layers.contains(&Layer::Conv) {
            return Err(VaeError::argument(
                "structure",
                format!("{s:?} has no convolution (C); at least one is needed"),
            ));
        }
        Ok(Self(layers))
    }
}

impl TryFrom<String> for Structure {
    type Error = VaeError;

    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<Structure> for String {
    fn from(s: Structure) -> Self {
        s.to_string()
    }
}

impl fmt::Display for Structure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for layer in &self.0 {
            f.write_str(match layer {
                Layer::Conv => "C",
                Layer::Pool => "P",
            })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_counts_and_prints_back() {
        for (s, convs, pools) in [
            ("CCPC", 3, 1),
            ("cpcpc", 3, 2),
            ("CCPCCPC", 5, 2),
            ("C", 1, 0),
        ] {
            let st: Structure = s.parse().unwrap();
            assert_eq!((st.convs(), st.pools()), (convs, pools), "{s}");
            assert_eq!(st.to_string(), s.to_uppercase());
        }
        assert_eq!(Structure::default().to_string(), "CCPC");
    }

    #[test]
    fn bad_strings_are_typed_errors_naming_the_character() {
        let err = "CCXC".parse::<Structure>().unwrap_err();
        assert!(matches!(err, VaeError::Argument { .. }));
        let msg = err.to_string();
        assert!(msg.contains("'X'") && msg.contains("position 2"), "{msg}");
        assert!(
            "PP".parse::<Structure>()
                .unwrap_err()
                .to_string()
                .contains("no convolution")
        );
        assert!("".parse::<Structure>().is_err());
    }

    #[test]
    fn serde_uses_the_string() {
        let st: Structure = "CPCPC".parse().unwrap();
        let json = serde_json::to_string(&st).unwrap();
        assert_eq!(json, "\"CPCPC\"");
        assert_eq!(serde_json::from_str::<Structure>(&json).unwrap(), st);
        assert!(serde_json::from_str::<Structure>("\"CQ\"").is_err());
    }
}
