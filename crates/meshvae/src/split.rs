//! [`Split`]: which meshes of a set train the model and which measure it.
//!
//! The paper splits each set "randomly into halves"; the authors' code draws ⌊N/2⌋ training
//! meshes with an unseeded generator. Here the draw comes from a seed (same seed, same split on
//! any machine) or from lists the user gives, and the split is saved with the model.

use crate::error::{Result, VaeError};
use crate::rng::Rng;
use serde::{Deserialize, Serialize};

/// Indices (into the mesh set) of the training and test meshes, each ascending.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Split {
    pub train: Vec<usize>,
    pub test: Vec<usize>,
}

impl Split {
    /// ⌊N·(1 − test_fraction)⌋ training meshes drawn from `seed` (at least one), the rest test.
    /// With N = 1 the one mesh trains and the test set is empty.
    pub fn random(n: usize, test_fraction: f64, seed: u64) -> Result<Self> {
        if n == 0 {
            return Err(VaeError::argument("mesh set", "is empty"));
        }
        if !(0.0..1.0).contains(&test_fraction) {
            return Err(VaeError::argument(
                "test fraction",
                format!("{test_fraction} is not in [0, 1)"),
            ));
        }
        let train_count = (((n as f64) * (1.0 - test_fraction)).floor() as usize).clamp(1, n);
        let mut order: Vec<usize> = (0..n).collect();
        Rng::new(seed).shuffle(&mut order);
        let mut train = order[..train_count].to_vec();
        let mut test = order[train_count..].to_vec();
        train.sort_unstable();
        test.sort_unstable();
        Ok(Self { train, test })
    }

    /// A split from explicit lists: indices in range, no repeats, disjoint, at least one
    /// training mesh. Meshes in neither list are left out.
    pub fn from_lists(n: usize, train: Vec<usize>, test: Vec<usize>) -> Result<Self> {
        let mut seen = vec![0u8; n];
        for (list, name, mark) in [(&train, "training list", 1u8), (&test, "test list", 2u8)] {
            for &i in list {
                if i >= n {
                    return Err(VaeError::argument(
                        name,
                        format!("index {i} is out of range (the set has {n} meshes)"),
                    ));
                }
                if seen[i] != 0 {
                    let other = if seen[i] == mark {
                        "twice"
                    } else {
                        "in both lists"
                    };
                    return Err(VaeError::argument(name, format!("mesh {i} is {other}")));
                }
                seen[i] = mark;
            }
        }
        if train.is_empty() {
            return Err(VaeError::argument("training list", "is empty"));
        }
        let (mut train, mut test) = (train, test);
        train.sort_unstable();
        test.sort_unstable();
        Ok(Self { train, test })
    }

    /// Resolves mesh names (or decimal indices) against the set's names.
    pub fn from_names(names: &[String], train: &[String], test: &[String]) -> Result<Self> {
        let resolve = |list: &[String], what: &str| -> Result<Vec<usize>> {
            list.iter().map(|s| resolve_mesh(names, s, what)).collect()
        };
        Self::from_lists(
            names.len(),
            resolve(train, "training list")?,
            resolve(test, "test list")?,
        )
    }

    /// Checks the split against a set of `n` meshes (e.g. when a model is loaded).
    pub fn check(&self, n: usize) -> Result<()> {
        Self::from_lists(n, self.train.clone(), self.test.clone()).map(|_| ())
    }
}

/// The index of a mesh given by name (as in the set) or by index.
pub fn resolve_mesh(names: &[String], key: &str, what: &str) -> Result<usize> {
    if let Some(i) = names.iter().position(|n| n == key) {
        return Ok(i);
    }
    if let Ok(i) = key.parse::<usize>()
        && i < names.len()
    {
        return Ok(i);
    }
    Err(VaeError::argument(
        what,
        format!(
            "no mesh named `{key}` (the set has {} meshes, e.g. `{}`)",
            names.len(),
            names.first().map(String::as_str).unwrap_or("")
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn random_split_is_a_seeded_partition_into_halves() {
        let a = Split::random(48, 0.5, 7).unwrap();
        assert_eq!((a.train.len(), a.test.len()), (24, 24));
        let mut all: Vec<usize> = a.train.iter().chain(&a.test).copied().collect();
        all.sort_unstable();
        assert_eq!(all, (0..48).collect::<Vec<_>>());
        assert_eq!(a, Split::random(48, 0.5, 7).unwrap());
        assert_ne!(a, Split::random(48, 0.5, 8).unwrap());
        // Odd counts: ⌊N/2⌋ train, as the authors.
        let b = Split::random(175, 0.5, 1).unwrap();
        assert_eq!((b.train.len(), b.test.len()), (87, 88));
        assert_eq!(Split::random(1, 0.5, 1).unwrap().train, vec![0]);
    }

    #[test]
    fn bad_lists_and_fractions_are_named_errors() {
        let err = |r: Result<Split>| r.unwrap_err().to_string();
        assert!(err(Split::from_lists(4, vec![0, 4], vec![1])).contains("out of range"));
        assert!(err(Split::from_lists(4, vec![0, 1], vec![1])).contains("in both lists"));
        assert!(err(Split::from_lists(4, vec![0, 0], vec![1])).contains("twice"));
        assert!(err(Split::from_lists(4, vec![], vec![1])).contains("training list"));
        assert!(err(Split::random(4, 1.0, 1)).contains("test fraction"));
        assert!(err(Split::random(0, 0.5, 1)).contains("empty"));
        let names: Vec<String> = ["a", "b", "c"].iter().map(|s| s.to_string()).collect();
        let s = Split::from_names(&names, &["c".into(), "0".into()], &["b".into()]).unwrap();
        assert_eq!((s.train, s.test), (vec![0, 2], vec![1]));
        assert!(err(Split::from_names(&names, &["zz".into()], &[])).contains("no mesh named `zz`"));
    }
}
