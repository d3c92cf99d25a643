//! [`Platform`]: the machine as far as training's numbers depend on it: the SIMD paths the
//! kernels and the matrix products pick at run time (AVX2 + FMA, AVX-512), and the data caches'
//! sizes, by which `gemm` blocks its products and so orders its sums. Two machines that differ
//! in either train the same run to other numbers: a last-bit difference in one step grows over
//! a thousand steps (on horse-gallop by mesh, seed 2: test RMS 0.0220 on one machine, 0.0249 on
//! another, same code and settings). Records of runs keep it, so that a rerun knows whether it
//! can expect the same bits.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;

/// The machine of a run, as far as its numbers depend on it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Platform {
    /// The CPU's model name (`/proc/cpuinfo`), for the reader.
    pub cpu: String,
    /// The SIMD features the kernels choose between, those present.
    pub simd: Vec<String>,
    /// The data caches ("L1d 48K L2 2048K L3 307200K"; empty where the system does not say).
    pub caches: String,
}

impl Platform {
    /// This machine.
    pub fn this() -> Self {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|info| {
                info.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split(':').nth(1))
                    .map(|name| name.trim().to_string())
            })
            .unwrap_or_default();
        Self {
            cpu,
            simd: simd(),
            caches: caches(),
        }
    }

    /// Whether runs give the same bits here and on `other`: the same SIMD features and caches
    /// (the model name alone does not decide it).
    pub fn same_numerics(&self, other: &Platform) -> bool {
        self.simd == other.simd && self.caches == other.caches
    }
}

impl fmt::Display for Platform {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let cpu = if self.cpu.is_empty() {
            "a CPU"
        } else {
            &self.cpu
        };
        write!(f, "{cpu} ({}; {})", self.simd.join(", "), self.caches)
    }
}

fn simd() -> Vec<String> {
    let mut out = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        let found = [
            ("avx2", std::arch::is_x86_feature_detected!("avx2")),
            ("fma", std::arch::is_x86_feature_detected!("fma")),
            ("avx512f", std::arch::is_x86_feature_detected!("avx512f")),
        ];
        out.extend(
            (found.iter())
                .filter(|(_, on)| *on)
                .map(|(name, _)| name.to_string()),
        );
    }
    out
}

fn caches() -> String {
    let mut out = Vec::new();
    for index in 0..8 {
        let dir = Path::new("/sys/devices/system/cpu/cpu0/cache").join(format!("index{index}"));
        let read = |f: &str| std::fs::read_to_string(dir.join(f)).map(|s| s.trim().to_string());
        let (Ok(level), Ok(kind), Ok(size)) = (read("level"), read("type"), read("size")) else {
            continue;
        };
        match kind.as_str() {
            "Data" => out.push(format!("L{level}d {size}")),
            "Unified" => out.push(format!("L{level} {size}")),
            _ => {}
        }
    }
    out.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn this_machine_is_itself_and_another_cache_is_not() {
        let here = Platform::this();
        assert!(here.same_numerics(&Platform::this()));
        let other = Platform {
            caches: "L1d 1K".into(),
            ..here.clone()
        };
        assert!(!here.same_numerics(&other));
        assert!(here.to_string().contains(&here.caches));
    }
}
