//! Times the training step `meshvae train` runs (the engine: forward, loss, backward, Adam) on
//! a set's template at batch 32, f32, and prints one JSON line with the same keys as
//! `benches/reference/pytorch_step.py`, so the two can be run one after the other in the same
//! spell of the machine (its speed drifts by 20–50 % between spells; see docs/benchmarks.md).
//! Beside them, the medians of the step's two phases (`forward_backward_ms`, `adam_ms`) and of
//! an inference pass over two meshes (`inference_2_meshes_ms`: the validation pass of a
//! horse-gallop run under the paper's split, every epoch).
//!
//! ```text
//! cargo run --release -p meshvae-benches --example step_time -- horse-gallop [--steps 30]
//! ```
//!
//! The set is a name under `MESHVAE_DATASETS` (or `../shared/datasets`) or a folder. The network
//! is `ModelConfig::default()` (the paper's CCPC); the input is random in (−0.95, 0.95), as in
//! the criterion bench `train`. The first three steps are dropped.

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use candle_core::{Device, Tensor};
use mesh_hierarchy::Hierarchy;
use meshvae::{Adam, Batch, EngineExecutor, Executor, LossWeights, MeshVae, ModelConfig, Rng};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

const BATCH: usize = 32;
const DROPPED: usize = 3;

fn main() -> ExitCode {
    match run() {
        Ok(line) => {
            println!("{line}");
            ExitCode::SUCCESS
        }
        Err(message) => {
            eprintln!("step_time: {message}");
            ExitCode::from(2)
        }
    }
}

fn run() -> Result<String, String> {
    let mut args = std::env::args().skip(1);
    let mut set_arg = None;
    let mut steps = 30usize;
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--steps" => {
                let value = args.next().ok_or("--steps: missing value")?;
                steps = value.parse().ok().filter(|&n| n > DROPPED).ok_or(format!(
                    "--steps: {value:?} is not an integer above {DROPPED}"
                ))?;
            }
            _ if set_arg.is_none() && !arg.starts_with('-') => set_arg = Some(arg),
            _ => return Err(format!("unexpected argument {arg:?}")),
        }
    }
    let set_arg = set_arg.ok_or("usage: step_time <SET> [--steps N]")?;
    let dir = mesh_io::datasets::find(&set_arg)
        .or_else(|| Some(PathBuf::from(&set_arg)).filter(|p| p.is_dir()))
        .ok_or(format!("{set_arg:?}: neither a data set name nor a folder"))?;
    let set = mesh_io::load_set(&dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .value;

    let config = ModelConfig::default();
    let hierarchy = Hierarchy::build(&set.template(), &config.hierarchy_config())
        .map_err(|e| format!("hierarchy: {e}"))?;
    let device = Device::Cpu;
    let model = MeshVae::new(&config, &hierarchy, &device, 1).map_err(|e| e.to_string())?;
    let mut adam = Adam::new(model.trainable_vars(), 1e-3).map_err(|e| e.to_string())?;
    let mut engine = EngineExecutor::new(&model, BATCH).map_err(|e| e.to_string())?;
    let mut rng = Rng::new(7);
    let v = set.vertex_count();
    let data: Vec<f32> = (0..BATCH * v * 9)
        .map(|_| (rng.uniform() * 1.9 - 0.95) as f32)
        .collect();
    let x = Tensor::from_vec(data, (BATCH, v, 9), &device).map_err(|e| e.to_string())?;
    let weights = LossWeights::default();

    let mut times = Vec::with_capacity(steps);
    let (mut fwd_bwd, mut adam_ms, mut infer_small) = (Vec::new(), Vec::new(), Vec::new());
    // The validation pass of a by-mesh split: two meshes, inference mode.
    let x_small = x.narrow(0, 0, 2).map_err(|e| e.to_string())?;
    for _ in 0..steps {
        let eps = rng
            .normal_tensor((BATCH, config.latent), &device)
            .map_err(|e| e.to_string())?;
        let start = Instant::now();
        engine
            .forward_backward(&model, &x, None, &eps, &weights)
            .map_err(|e| e.to_string())?;
        let mid = Instant::now();
        engine
            .apply_adam(&mut adam, weights.l2)
            .map_err(|e| e.to_string())?;
        let end = Instant::now();
        engine
            .rec_error(
                &model,
                Batch {
                    x: &x_small,
                    c: None,
                },
                &weights,
            )
            .map_err(|e| e.to_string())?;
        infer_small.push(end.elapsed().as_secs_f64() * 1e3);
        fwd_bwd.push((mid - start).as_secs_f64() * 1e3);
        adam_ms.push((end - mid).as_secs_f64() * 1e3);
        times.push((end - start).as_secs_f64() * 1e3);
    }
    let median = |mut v: Vec<f64>| {
        let mut kept = v.split_off(DROPPED);
        kept.sort_by(f64::total_cmp);
        kept[(kept.len() - 1) / 2]
    };
    let (fwd_bwd, adam_ms, infer_small) = (median(fwd_bwd), median(adam_ms), median(infer_small));
    let mut kept = times.split_off(DROPPED);
    kept.sort_by(f64::total_cmp);
    let quantile = |q: f64| kept[((kept.len() - 1) as f64 * q).round() as usize];
    Ok(format!(
        "{{\"vertices\": {v}, \"batch\": {BATCH}, \"threads\": {}, \"steps\": {}, \
         \"median_ms\": {:.1}, \"p10_ms\": {:.1}, \"p90_ms\": {:.1}, \"peak_rss_mb\": {}, \
         \"forward_backward_ms\": {fwd_bwd:.1}, \"adam_ms\": {adam_ms:.1}, \
         \"inference_2_meshes_ms\": {infer_small:.1}}}",
        rayon_threads(),
        kept.len(),
        quantile(0.5),
        quantile(0.1),
        quantile(0.9),
        peak_rss_mb().map_or("null".to_string(), |mb| mb.to_string()),
    ))
}

/// The threads the engine's rayon pool has (`RAYON_NUM_THREADS`, or the cores).
fn rayon_threads() -> usize {
    std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|s| s.parse().ok())
        .filter(|&n| n > 0)
        .or_else(|| std::thread::available_parallelism().ok().map(usize::from))
        .unwrap_or(1)
}

/// Peak resident memory (`VmHWM` of /proc/self/status), Linux only.
fn peak_rss_mb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024)
}
