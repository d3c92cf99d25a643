//! The conditional VAE's acceptance test: samples generated with label c have their
//! nearest training mesh among the meshes labelled c, for at least 80 % of the samples and for
//! each label — on horse-gallop + horse-poses (`gallop` / `pose`, joined in code; skipped
//! without the data) and on the synthetic bend / twist set.

use candle_core::Device;
use mesh_io::{MeshSet, datasets};
use meshvae::{
    GenerateOptions, ModelConfig, Schedule, Split, TrainConfig, TrainOptions, TrainRequest,
    TrainedModel,
};
use std::path::Path;
use std::time::Instant;

/// Samples generated per label.
const SAMPLES: usize = 20;
/// The acceptance threshold.
const SHARE: f64 = 0.8;

/// Every other mesh of each label trains, the rest validate (choose the checkpoint): both
/// labels are in the training split whatever their sizes (the synthetic set).
fn stratified_split(labels: &[String]) -> Split {
    let (mut train, mut val) = (Vec::new(), Vec::new());
    let mut seen: Vec<(&String, usize)> = Vec::new();
    for (i, l) in labels.iter().enumerate() {
        let k = match seen.iter_mut().find(|(s, _)| *s == l) {
            Some((_, k)) => {
                *k += 1;
                *k
            }
            None => {
                seen.push((l, 0));
                0
            }
        };
        if k % 2 == 0 {
            train.push(i);
        } else {
            val.push(i);
        }
    }
    Split::from_three_lists(labels.len(), train, val, Vec::new()).unwrap()
}

/// horse-gallop + horse-poses with balanced labels: every 4th gallop frame (12) and all 10
/// poses train; two gallop frames validate (choose the checkpoint). With the natural 48 : 10, or
/// every other mesh of each label (24 : 5), the five poses are too few: samples asked for
/// `pose` came out as gallop frames (10 %, see docs/benchmarks.md).
fn balanced_horse_split(labels: &[String]) -> Split {
    let (mut train, mut val) = (Vec::new(), Vec::new());
    for (i, l) in labels.iter().enumerate() {
        if l != "gallop" || i % 4 == 0 {
            train.push(i);
        } else if val.len() < 2 {
            val.push(i);
        }
    }
    Split::from_three_lists(labels.len(), train, val, Vec::new()).unwrap()
}

/// Trains a conditional model on `set` (labelled) with `split` and returns, per label, the
/// share of samples whose nearest training mesh carries it.
fn label_shares(
    set: &MeshSet,
    name: &str,
    split: Split,
    model: ModelConfig,
    train: TrainConfig,
) -> Vec<(String, f64)> {
    let labels = set.labels().unwrap().to_vec();
    let out = std::env::temp_dir().join(format!("e2e-cvae-{name}-{}", std::process::id()));
    let request = TrainRequest {
        set,
        source: None,
        out: out.clone(),
        model: model.conditional_on(&labels),
        train,
        features: Default::default(),
        hierarchy: Default::default(),
        split: Some(split),
    };
    let options = TrainOptions {
        force: true,
        checkpoint_seconds: 1e9,
        ..TrainOptions::default()
    };
    let t0 = Instant::now();
    meshvae::train(&request, &options, |_| {}).unwrap();
    let trained = TrainedModel::load(&out, &Device::Cpu).unwrap();
    eprintln!("{name}: trained in {:.1} s", t0.elapsed().as_secs_f64());
    assert_eq!(trained.model.labels(), set.distinct_labels().unwrap());
    assert_eq!(trained.mesh_labels(), Some(labels.as_slice()));
    // The folder records the labels (config.json: the model's and each mesh's).
    let config = std::fs::read_to_string(out.join("config.json")).unwrap();
    assert!(config.matches("\"labels\"").count() == 2, "{config}");

    let options = GenerateOptions {
        count: SAMPLES,
        seed: 3,
    };
    let mut shares = Vec::new();
    for label in trained.model.labels().to_vec() {
        let g = trained
            .generate_labelled(set, &options, Some(&label))
            .unwrap();
        assert_eq!(g.label.as_deref(), Some(label.as_str()));
        for nb in &g.nearest {
            assert!(trained.split.train.contains(&nb.index));
            assert_eq!(nb.label.as_ref(), Some(&labels[nb.index]));
        }
        let share = g.label_share().unwrap();
        eprintln!(
            "{name}: label {label}: {:.0} % of samples nearest to a {label} mesh",
            100.0 * share
        );
        shares.push((label, share));
    }
    // The same z with the other label decodes other meshes: the decoder uses the label.
    let all: Vec<_> = trained
        .model
        .labels()
        .iter()
        .map(|l| {
            trained
                .generate_labelled(set, &GenerateOptions { count: 1, seed: 3 }, Some(l))
                .unwrap()
                .positions
        })
        .collect();
    assert_ne!(all[0], all[1]);
    let _ = std::fs::remove_dir_all(&out);
    shares
}

fn assert_shares(shares: &[(String, f64)]) {
    assert_eq!(shares.len(), 2);
    for (label, share) in shares {
        assert!(
            *share >= SHARE,
            "label {label}: only {:.0} % of the samples are nearest to a {label} mesh ({shares:?})",
            100.0 * share
        );
    }
}

#[test]
fn synthetic_bend_twist_samples_follow_their_label() {
    let set = mesh_io::synth::generate(&mesh_io::synth::SynthConfig {
        meshes_per_label: 20,
        rings: 8,
        segments: 10,
        cap_rings: 2,
        ..Default::default()
    })
    .unwrap()
    .set;
    assert_eq!(set.distinct_labels().unwrap(), ["bend", "twist"]);
    let split = stratified_split(set.labels().unwrap());
    let shares = label_shares(
        &set,
        "synth",
        split,
        ModelConfig {
            latent: 16,
            ..ModelConfig::default()
        },
        TrainConfig {
            epochs: SYNTH_EPOCHS,
            batch: 4,
            loss: KL_HEAVY,
            // The optimiser, constant schedule and min–max feature ranges the shares were
            // measured with.
            lr: 1e-3,
            schedule: Schedule::constant(),
            normalize_quantile: 0.0,
            adam_beta2: 0.999,
            head_lr_scale: 1.0,
            grad_clip: 0.0,
            ..TrainConfig::default()
        },
    );
    assert_shares(&shares);
}

/// Epochs (see the figures in docs/benchmarks.md, "Conditional VAE").
const SYNTH_EPOCHS: usize = 300;
const HORSE_EPOCHS: usize = 100;

/// The KL weight 10× the authors' 3: the posterior stays nearer N(0, I), so the label rather
/// than z carries the class (with 3: 75 % / 45 % on the synthetic set, see cvae.md).
const KL_HEAVY: meshvae::LossWeights = meshvae::LossWeights {
    rec: 40.0,
    kl: 30.0,
    l2: 1.0,
};

#[test]
fn horse_gallop_and_poses_samples_follow_their_label() {
    let (Some(gallop), Some(poses)) = (
        datasets::find_or_skip("horse-gallop"),
        datasets::find_or_skip("horse-poses"),
    ) else {
        return;
    };
    let set = joined(&[(&gallop, "gallop"), (&poses, "pose")]);
    assert_eq!(set.len(), 58);
    let split = balanced_horse_split(set.labels().unwrap());
    let shares = label_shares(
        &set,
        "horse",
        split,
        ModelConfig {
            latent: 32,
            ..ModelConfig::default()
        },
        TrainConfig {
            epochs: HORSE_EPOCHS,
            batch: 4,
            loss: KL_HEAVY,
            // The optimiser, constant schedule and min–max feature ranges the shares were
            // measured with.
            lr: 1e-3,
            schedule: Schedule::constant(),
            normalize_quantile: 0.0,
            adam_beta2: 0.999,
            head_lr_scale: 1.0,
            grad_clip: 0.0,
            ..TrainConfig::default()
        },
    );
    assert_shares(&shares);
}

/// The sets in `dirs` as one set, each mesh labelled by its set (what `meshvae pack A B` does).
fn joined(dirs: &[(&Path, &str)]) -> MeshSet {
    let mut positions = Vec::new();
    let (mut names, mut labels) = (Vec::new(), Vec::new());
    let mut first: Option<MeshSet> = None;
    for (dir, label) in dirs {
        let set = mesh_io::load_set(dir).unwrap().value;
        if let Some(f) = &first {
            assert_eq!(f.faces(), set.faces(), "{}", dir.display());
        }
        positions.extend_from_slice(set.positions());
        names.extend(set.names().iter().map(|n| format!("{label}_{n}")));
        labels.extend(std::iter::repeat_n(label.to_string(), set.len()));
        first.get_or_insert(set);
    }
    let first = first.unwrap();
    MeshSet::from_flat(
        first.faces().to_vec(),
        first.vertex_count(),
        positions,
        names,
    )
    .unwrap()
    .with_labels(labels)
    .unwrap()
}
