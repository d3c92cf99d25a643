//! The network through its public API: shapes and ranges for every structure, convolution and
//! pooling; the loss's gradient against finite differences in f64; determinism, save/load, and
//! typed errors for bad input.

use candle_core::{DType, Device, Tensor, Var};
use mesh_hierarchy::Hierarchy;
use meshvae::{
    Adam, ConvKind, LossWeights, MeshVae, Mode, ModelConfig, Pooler, Rng, VaeError, param_count,
};
use std::collections::HashMap;
use std::path::PathBuf;

/// Hierarchies of the 162-vertex icosphere, one per (pooler, depth).
struct Hierarchies(HashMap<(Pooler, usize), Hierarchy>);

impl Hierarchies {
    fn new() -> Self {
        Self(HashMap::new())
    }

    fn get(&mut self, config: &ModelConfig) -> &Hierarchy {
        self.0
            .entry((config.pool, config.pool_levels()))
            .or_insert_with(|| {
                let sphere = qem_simplify::shapes::icosphere(2);
                Hierarchy::build(&sphere, &config.hierarchy_config()).unwrap()
            })
    }
}

/// Features in [−0.95, 0.95], as the normalised training data.
fn features(batch: usize, v: usize, dtype: DType, seed: u64) -> Tensor {
    let mut rng = Rng::new(seed);
    let values: Vec<f64> = (0..batch * v * 9)
        .map(|_| 1.9 * rng.uniform() - 0.95)
        .collect();
    Tensor::from_vec(values, (batch, v, 9), &Device::Cpu)
        .unwrap()
        .to_dtype(dtype)
        .unwrap()
}

fn noise(batch: usize, latent: usize, dtype: DType, seed: u64) -> Tensor {
    let mut rng = Rng::new(seed);
    Tensor::from_vec(rng.normals(batch * latent), (batch, latent), &Device::Cpu)
        .unwrap()
        .to_dtype(dtype)
        .unwrap()
}

fn values(t: &Tensor) -> Vec<f64> {
    t.flatten_all()
        .unwrap()
        .to_dtype(DType::F64)
        .unwrap()
        .to_vec1()
        .unwrap()
}

fn var(model: &MeshVae, name: &str) -> Var {
    model
        .trainable_vars()
        .into_iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("no variable {name}"))
        .1
}

fn temp_path(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("meshvae-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn every_structure_conv_and_pool_gives_the_right_shapes_and_ranges() {
    let mut hierarchies = Hierarchies::new();
    let dev = Device::Cpu;
    for structure in ["CCPC", "CPCPC", "CCPCCPC", "C"] {
        for conv in [ConvKind::Spectral, ConvKind::Spatial] {
            for pool in Pooler::ALL {
                let config = ModelConfig {
                    structure: structure.parse().unwrap(),
                    conv,
                    pool,
                    latent: 16,
                    ..Default::default()
                };
                let case = format!("{structure} {conv} {pool}");
                let h = hierarchies.get(&config);
                let model = MeshVae::new(&config, h, &dev, 7).unwrap();
                let v = model.vertex_count();
                assert_eq!(v, 162);
                let x = features(3, v, DType::F32, 1);
                let eps = noise(3, 16, DType::F32, 2);
                let (x_hat, enc) = model.forward(&x, None, &eps, Mode::Train).unwrap();
                assert_eq!(enc.mu.dims(), &[3, 16], "{case}");
                assert_eq!(enc.sigma.dims(), &[3, 16], "{case}");
                assert_eq!(x_hat.dims(), &[3, v, 9], "{case}");
                let sqrt2 = 2f64.sqrt();
                assert!(
                    values(&enc.sigma).iter().all(|&s| s > 0.0 && s < sqrt2),
                    "{case}"
                );
                let out = values(&x_hat);
                assert!(out.iter().all(|&y| y > -1.0 && y < 1.0), "{case}");
                // The output varies (not a constant from a dead network).
                let spread = out.iter().cloned().fold(f64::MIN, f64::max)
                    - out.iter().cloned().fold(f64::MAX, f64::min);
                assert!(spread > 1e-4, "{case}: spread {spread}");
                let rec = model.reconstruct(&x, None).unwrap();
                assert_eq!(rec.dims(), &[3, v, 9], "{case}");
                // The formula agrees with the variables actually created.
                let counted = model.param_count();
                assert_eq!(
                    counted,
                    param_count(&config, model.vertex_counts()),
                    "{case}"
                );
                let scalars: usize = model
                    .trainable_vars()
                    .iter()
                    .map(|(_, v)| v.elem_count())
                    .sum();
                assert_eq!(counted.with_biases, scalars, "{case}");
                let levels = structure.matches('P').count() + 1;
                assert_eq!(model.vertex_counts().len(), levels, "{case}");
                if pool == Pooler::None {
                    assert!(model.vertex_counts().iter().all(|&n| n == v), "{case}");
                } else if structure != "C" {
                    assert!(model.vertex_counts()[1] < v, "{case}");
                }
            }
        }
    }
}

/// Error of the autodiff gradient against central differences (h = 1e-4, f64), worst over a
/// few entries (first, middle, last) of every trainable variable.
fn gradient_check(config: &ModelConfig, hierarchies: &mut Hierarchies) -> (f64, String) {
    let h = hierarchies.get(config);
    let model = MeshVae::with_dtype(config, h, &Device::Cpu, DType::F64, 3).unwrap();
    let (v, latent) = (model.vertex_count(), model.latent());
    let x = features(2, v, DType::F64, 4);
    let eps = noise(2, latent, DType::F64, 5);
    let weights = LossWeights::default();
    let loss = || -> f64 {
        let l = model.loss(&x, None, &eps, &weights).unwrap();
        l.total.to_scalar::<f64>().unwrap()
    };
    let grads = model
        .backward(&model.loss(&x, None, &eps, &weights).unwrap().total)
        .unwrap();
    let step = 1e-4;
    let (mut worst, mut at) = (0.0f64, String::new());
    for (name, var) in model.trainable_vars() {
        let n = var.elem_count();
        let grad = values(
            grads
                .get(&var)
                .unwrap_or_else(|| panic!("no gradient for {name}")),
        );
        let original = var.as_tensor().copy().unwrap();
        let base = values(&original);
        for i in [0, n / 2, n - 1] {
            let probe = |delta: f64| {
                let mut w = base.clone();
                w[i] += delta;
                var.set(&Tensor::from_vec(w, var.shape(), &Device::Cpu).unwrap())
                    .unwrap();
                loss()
            };
            let fd = (probe(step) - probe(-step)) / (2.0 * step);
            var.set(&original).unwrap();
            // Relative for gradients above 1, absolute below: the loss is ~10⁴, so the central
            // difference's own error (h² truncation, rounding) is ~10⁻⁶ in absolute terms.
            let err = (grad[i] - fd).abs() / grad[i].abs().max(fd.abs()).max(1.0);
            if err > worst {
                worst = err;
                at = format!("{name}[{i}]: autodiff {} vs fd {fd}", grad[i]);
            }
        }
    }
    (worst, at)
}

#[test]
fn loss_gradients_match_finite_differences_in_f64() {
    let mut hierarchies = Hierarchies::new();
    let small = ModelConfig {
        latent: 6,
        channels: 4,
        // Larger weights than 0.02 so that tanh and batch norm work away from their linear
        // regime and a wrong derivative shows.
        init_std: 0.3,
        ..Default::default()
    };
    let configs = [
        small.clone(),
        ModelConfig {
            structure: "CPCPC".parse().unwrap(),
            conv: ConvKind::Spatial,
            pool: Pooler::Sampling,
            tie_decoder_convs: true,
            ..small.clone()
        },
        ModelConfig {
            pool: Pooler::Max,
            last_encoder_linear: false,
            ..small.clone()
        },
        ModelConfig {
            structure: "CPC".parse().unwrap(),
            pool: Pooler::None,
            tie_decoder_convs: true,
            batch_norm: false,
            ..small
        },
    ];
    for config in &configs {
        let (worst, at) = gradient_check(config, &mut hierarchies);
        assert!(
            worst < 1e-5,
            "{} {} {}: {worst} at {at}",
            config.structure,
            config.conv,
            config.pool
        );
    }
}

#[test]
fn loss_terms_have_the_documented_values() {
    let mut hierarchies = Hierarchies::new();
    let config = ModelConfig {
        latent: 8,
        ..Default::default()
    };
    let model = MeshVae::with_dtype(
        &config,
        hierarchies.get(&config),
        &Device::Cpu,
        DType::F64,
        1,
    )
    .unwrap();
    let x = features(3, 162, DType::F64, 1);
    let eps = noise(3, 8, DType::F64, 2);
    let w = LossWeights {
        rec: 2.0,
        kl: 0.5,
        l2: 0.25,
    };
    // The reference terms come from the train-mode forward pass of a twin (same seed).
    let twin = MeshVae::with_dtype(
        &config,
        hierarchies.get(&config),
        &Device::Cpu,
        DType::F64,
        1,
    )
    .unwrap();
    let loss = model.loss(&x, None, &eps, &w).unwrap();
    let (x_hat, enc) = twin.forward(&x, None, &eps, Mode::Train).unwrap();
    let sse: f64 = values(&x)
        .iter()
        .zip(values(&x_hat))
        .map(|(a, b)| (a - b).powi(2))
        .sum();
    assert!((loss.rec - 2.0 * sse / 3.0).abs() < 1e-9 * loss.rec);
    let kl: f64 = values(&enc.mu)
        .iter()
        .zip(values(&enc.sigma))
        .map(|(m, s)| 0.5 * (m * m + s * s - (1e-8 + s * s).ln() - 1.0))
        .sum();
    assert!((loss.kl - 0.5 * kl / 3.0).abs() < 1e-9 * loss.kl.abs().max(1e-12));
    let l2: f64 = model
        .trainable_vars()
        .iter()
        .map(|(_, v)| {
            values(v.as_tensor())
                .iter()
                .map(|w| 0.5 * w * w)
                .sum::<f64>()
        })
        .sum();
    assert!((loss.l2 - 0.25 * l2).abs() < 1e-9 * loss.l2);
    let total: f64 = loss.total.to_scalar().unwrap();
    assert!((total - (loss.rec + loss.kl + loss.l2)).abs() < 1e-9 * total);
    // The L2 term includes biases and γ: γ = 1 contributes ½ per channel of each batch norm.
    assert!(l2 > 4.0 * 9.0 * 0.5);
    // Validation: w_rec · mean SSE of decode(μ) in eval mode.
    let rec = model.reconstruct(&x, None).unwrap();
    let sse: f64 = values(&x)
        .iter()
        .zip(values(&rec))
        .map(|(a, b)| (a - b).powi(2))
        .sum();
    let val = model.rec_error(&x, None, &w).unwrap();
    assert!((val - 2.0 * sse / 3.0).abs() < 1e-9 * val);
}

#[test]
fn the_decoder_dense_layer_follows_the_mu_head() {
    let mut hierarchies = Hierarchies::new();
    let config = ModelConfig {
        latent: 8,
        ..Default::default()
    };
    let model = MeshVae::new(&config, hierarchies.get(&config), &Device::Cpu, 1).unwrap();
    let z = noise(2, 8, DType::F32, 3);
    let before = values(&model.decode(&z, None, Mode::Eval).unwrap());
    let w_mu = var(&model, "enc.mu.weight");
    w_mu.set(&(w_mu.as_tensor() * 3.0).unwrap()).unwrap();
    let after = values(&model.decode(&z, None, Mode::Eval).unwrap());
    let change = before
        .iter()
        .zip(&after)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(change > 1e-4, "{change}");
    // W_σ does not take part in decoding.
    let w_sigma = var(&model, "enc.sigma.weight");
    w_sigma.set(&(w_sigma.as_tensor() * 3.0).unwrap()).unwrap();
    assert_eq!(values(&model.decode(&z, None, Mode::Eval).unwrap()), after);
}

#[test]
fn training_steps_lower_the_loss() {
    let mut hierarchies = Hierarchies::new();
    let config = ModelConfig {
        latent: 16,
        ..Default::default()
    };
    let model = MeshVae::new(&config, hierarchies.get(&config), &Device::Cpu, 5).unwrap();
    let mut adam = Adam::new(model.trainable_vars(), 1e-3).unwrap();
    // Learnable data: a common smooth field over the sphere plus a per-shape multiple of a
    // second one (uniform noise could not be reconstructed better than by its mean).
    let sphere = qem_simplify::shapes::icosphere(2);
    let mut data = Vec::new();
    for b in 0..4 {
        for p in &sphere.positions {
            for c in 0..9 {
                let (x, y) = (p[0] as f64, p[1] as f64);
                let common = 0.5 * (3.0 * x + c as f64).sin();
                data.push((common + 0.1 * (b as f64 - 1.5) * (2.0 * y).cos()) as f32);
            }
        }
    }
    let x = Tensor::from_vec(data, (4, 162, 9), &Device::Cpu).unwrap();
    let weights = LossWeights::default();
    let first = model.rec_error(&x, None, &weights).unwrap();
    let mut rng = Rng::new(1);
    for _ in 0..30 {
        let eps = rng.normal_tensor((4, 16), &Device::Cpu).unwrap();
        let loss = model.loss(&x, None, &eps, &weights).unwrap();
        adam.step(&model.backward(&loss.total).unwrap()).unwrap();
    }
    let last = model.rec_error(&x, None, &weights).unwrap();
    assert!(last < 0.9 * first, "{first} → {last}");
}

#[test]
fn same_seed_same_model_and_save_load_round_trips() {
    let mut hierarchies = Hierarchies::new();
    let config = ModelConfig {
        latent: 8,
        ..Default::default()
    };
    let h = hierarchies.get(&config).clone();
    let dev = Device::Cpu;
    let a = MeshVae::new(&config, &h, &dev, 11).unwrap();
    let b = MeshVae::new(&config, &h, &dev, 11).unwrap();
    let c = MeshVae::new(&config, &h, &dev, 12).unwrap();
    let (ta, tb, tc) = (
        a.tensors().unwrap(),
        b.tensors().unwrap(),
        c.tensors().unwrap(),
    );
    for (name, t) in &ta {
        assert_eq!(values(t), values(&tb[name]), "{name}");
    }
    assert_ne!(
        values(&ta["enc.conv0.weight"]),
        values(&tc["enc.conv0.weight"])
    );
    // Weights are N(0, 0.02²), biases and β 0, γ 1.
    let w = values(&ta["enc.mu.weight"]);
    let sd = (w.iter().map(|x| x * x).sum::<f64>() / w.len() as f64).sqrt();
    assert!((sd - 0.02).abs() < 0.001, "{sd}");
    assert!(values(&ta["enc.mu.bias"]).iter().all(|&x| x == 0.0));
    assert!(values(&ta["enc.bn0.gamma"]).iter().all(|&x| x == 1.0));
    assert!(values(&ta["enc.bn0.running_var"]).iter().all(|&x| x == 1.0));

    let x = features(2, 162, DType::F32, 1);
    let eps = noise(2, 8, DType::F32, 2);
    let weights = LossWeights::default();
    let la = a.loss(&x, None, &eps, &weights).unwrap();
    let lb = b.loss(&x, None, &eps, &weights).unwrap();
    assert_eq!(
        la.total.to_scalar::<f32>().unwrap(),
        lb.total.to_scalar::<f32>().unwrap()
    );
    // A training step moves a's weights and running statistics away from c's and b's.
    let mut adam = Adam::new(a.trainable_vars(), 1e-3).unwrap();
    adam.step(&a.backward(&la.total).unwrap()).unwrap();
    let path = temp_path("a.safetensors");
    a.save(&path).unwrap();
    let mut loaded = MeshVae::new(&config, &h, &dev, 99).unwrap();
    loaded.load(&path).unwrap();
    assert_eq!(
        values(&a.reconstruct(&x, None).unwrap()),
        values(&loaded.reconstruct(&x, None).unwrap())
    );
    let ta = a.tensors().unwrap();
    for (name, t) in loaded.tensors().unwrap() {
        assert_eq!(values(&t), values(&ta[&name]), "{name}");
    }
    assert_ne!(
        values(&ta["enc.bn0.running_mean"]),
        values(&tb["enc.bn0.running_mean"])
    );

    // Another configuration: same shapes (qem) or other shapes (latent) are both refused.
    let qem = ModelConfig {
        pool: Pooler::Qem,
        ..config.clone()
    };
    let mut other = MeshVae::new(&qem, hierarchies.get(&qem), &dev, 1).unwrap();
    let before = other.tensors().unwrap();
    let err = other.load(&path).unwrap_err();
    assert!(matches!(err, VaeError::Model { .. }));
    assert!(err.to_string().contains("pool"), "{err}");
    for (name, t) in other.tensors().unwrap() {
        assert_eq!(values(&t), values(&before[&name]), "{name} changed");
    }
    let wide = ModelConfig {
        latent: 9,
        ..config.clone()
    };
    let mut other = MeshVae::new(&wide, &h, &dev, 1).unwrap();
    let err = other.load(&path).unwrap_err().to_string();
    assert!(
        err.contains("latent") && err.contains("a.safetensors"),
        "{err}"
    );
    // Same config, other vertex count: the shapes are named.
    let small = Hierarchy::build(
        &qem_simplify::shapes::icosphere(1),
        &config.hierarchy_config(),
    )
    .unwrap();
    let mut other = MeshVae::new(&config, &small, &dev, 1).unwrap();
    let err = other.load(&path).unwrap_err().to_string();
    assert!(
        err.contains("enc.mu.weight") && err.contains("shape"),
        "{err}"
    );
    // Not a weight file; a missing file.
    let junk = temp_path("junk.safetensors");
    std::fs::write(&junk, b"not safetensors").unwrap();
    assert!(matches!(loaded.load(&junk), Err(VaeError::Model { .. })));
    assert!(matches!(
        loaded.load(&temp_path("missing.safetensors")),
        Err(VaeError::Io { .. })
    ));
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

fn shape_err<T>(r: meshvae::Result<T>) -> String {
    match r {
        Err(VaeError::Shape { what, .. }) => what,
        Err(e) => panic!("wrong error kind: {e}"),
        Ok(_) => panic!("accepted"),
    }
}

#[test]
fn bad_input_is_a_typed_error() {
    let mut hierarchies = Hierarchies::new();
    let config = ModelConfig {
        latent: 8,
        ..Default::default()
    };
    let model = MeshVae::new(&config, hierarchies.get(&config), &Device::Cpu, 1).unwrap();
    let msg = shape_err(model.encode(&features(2, 161, DType::F32, 1), None, Mode::Eval));
    assert!(msg.contains("162"), "{msg}");
    let eight = Tensor::zeros((2, 162, 8), DType::F32, &Device::Cpu).unwrap();
    shape_err(model.encode(&eight, None, Mode::Eval));
    let rank2 = Tensor::zeros((162, 9), DType::F32, &Device::Cpu).unwrap();
    shape_err(model.encode(&rank2, None, Mode::Eval));
    let empty = Tensor::zeros((0, 162, 9), DType::F32, &Device::Cpu).unwrap();
    shape_err(model.encode(&empty, None, Mode::Eval));
    let msg = shape_err(model.encode(&features(2, 162, DType::F64, 1), None, Mode::Eval));
    assert!(msg.contains("F64"), "{msg}");
    let x = features(2, 162, DType::F32, 1);
    shape_err(model.forward(&x, None, &noise(3, 8, DType::F32, 1), Mode::Train));
    shape_err(model.forward(&x, None, &noise(2, 7, DType::F32, 1), Mode::Train));
    shape_err(model.decode(&noise(2, 9, DType::F32, 1), None, Mode::Eval));
    let bad = ModelConfig {
        latent: 0,
        ..config
    };
    assert!(matches!(
        MeshVae::new(&bad, hierarchies.get(&bad), &Device::Cpu, 1),
        Err(VaeError::Argument { .. })
    ));
}

#[test]
fn l2_applied_by_adam_equals_l2_through_autograd() {
    let mut hierarchies = Hierarchies::new();
    let config = ModelConfig {
        latent: 16,
        ..Default::default()
    };
    let h = hierarchies.get(&config).clone();
    let a = MeshVae::new(&config, &h, &Device::Cpu, 9).unwrap();
    let b = MeshVae::new(&config, &h, &Device::Cpu, 9).unwrap();
    let mut adam_a = Adam::new(a.trainable_vars(), 1e-3).unwrap();
    let mut adam_b = Adam::new(b.trainable_vars(), 1e-3).unwrap();
    let weights = LossWeights::default();
    for step in 0..3 {
        let x = features(4, 162, DType::F32, 20 + step);
        let eps = noise(4, 16, DType::F32, 30 + step);
        let full = a.loss(&x, None, &eps, &weights).unwrap();
        adam_a.step(&a.backward(&full.total).unwrap()).unwrap();
        let split = b.training_loss(&x, None, &eps, &weights).unwrap();
        assert!(
            (split.l2 - full.l2).abs() <= 1e-5 * full.l2,
            "{} vs {}",
            split.l2,
            full.l2
        );
        adam_b
            .step_with_l2(&b.backward(&split.total).unwrap(), weights.l2)
            .unwrap();
    }
    for ((name, va), (_, vb)) in a.trainable_vars().iter().zip(b.trainable_vars()) {
        let (pa, pb) = (values(va.as_tensor()), values(vb.as_tensor()));
        let worst = pa
            .iter()
            .zip(&pb)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        // Both are three Adam steps of size ≤ 1e-3 from the same start: a missing or doubled L2
        // gradient would move some weights by ~1e-3.
        assert!(worst < 2e-5, "{name}: differs by {worst}");
    }
}
