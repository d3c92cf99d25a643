//! The engine against candle's autograd (the reference): loss terms, every gradient, the batch
//! norms' running statistics, whole training runs, and bit-reproducibility across thread
//! counts.

use super::*;
use crate::candle::batch_norm::Mode;
use crate::executor::{Batch, Executor};
use crate::net::config::{ConvKind, ModelConfig};
use crate::numerics::rng::Rng;
use candle_core::Device;
use mesh_hierarchy::Hierarchy;
use mesh_hierarchy::Pooler;

fn hierarchy(config: &ModelConfig) -> Hierarchy {
    let sphere = qem_simplify::shapes::icosphere(2);
    Hierarchy::build(&sphere, &config.hierarchy_config()).unwrap()
}

/// Two identical models (same seed): one for each path, since both move running statistics.
fn models(config: &ModelConfig, dtype: DType) -> (MeshVae, MeshVae) {
    let h = hierarchy(config);
    let m = || MeshVae::with_dtype(config, &h, &Device::Cpu, dtype, 7).unwrap();
    (m(), m())
}

fn inputs(model: &MeshVae, batch: usize, seed: u64) -> (Tensor, Tensor) {
    let mut rng = Rng::new(seed);
    let v = model.vertex_count();
    let x: Vec<f64> = rng
        .normals(batch * v * 9)
        .into_iter()
        .map(|x| (0.5 * x).tanh())
        .collect();
    let x = Tensor::from_vec(x, (batch, v, 9), &Device::Cpu).unwrap();
    let eps = rng
        .normal_tensor((batch, model.latent()), &Device::Cpu)
        .unwrap();
    let dtype = model.dtype();
    (x.to_dtype(dtype).unwrap(), eps.to_dtype(dtype).unwrap())
}

fn values(t: &Tensor) -> Vec<f64> {
    let flat = t.flatten_all().and_then(|t| t.to_dtype(DType::F64));
    flat.and_then(|t| t.to_vec1()).unwrap()
}

/// max |a − b| / max(max |b|, floor).
fn rel_diff(a: &[f64], b: &[f64], floor: f64) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(floor, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// For a conditional model: one-hot labels cycling through its labels, and the same random
/// label weights in both models (they start at zero, which would hide their forward use).
fn labels(reference: &MeshVae, ours: &MeshVae, batch: usize) -> Option<Tensor> {
    let names = reference.labels();
    if names.is_empty() {
        return None;
    }
    for (k, name) in crate::net::vars::LABEL_NAMES.iter().enumerate() {
        for model in [reference, ours] {
            let (_, var) = model
                .trainable_vars()
                .into_iter()
                .find(|(n, _)| n == name)
                .unwrap();
            let mut rng = Rng::new(60 + k as u64);
            let t = rng.normal_tensor(var.dims(), &Device::Cpu).unwrap();
            var.set(&(t * 0.1).unwrap().to_dtype(var.dtype()).unwrap())
                .unwrap();
        }
    }
    let picked: Vec<&String> = (0..batch).map(|b| &names[(b * 2) % names.len()]).collect();
    Some(reference.one_hot(&picked).unwrap())
}

/// One step on both paths; asserts the loss terms, gradients and running stats agree to `tol`.
fn compare_step(config: &ModelConfig, dtype: DType, batch: usize, tol: f64) {
    let (reference, ours) = models(config, dtype);
    let weights = LossWeights {
        rec: 40.0,
        kl: 3.0,
        l2: 1.0,
    };
    let (x, eps) = inputs(&reference, batch, 3);
    let c = labels(&reference, &ours, batch);
    let loss = reference
        .training_loss(&x, c.as_ref(), &eps, &weights)
        .unwrap();
    let grads = reference.backward(&loss.total).unwrap();
    let mut engine = EngineExecutor::new(&ours, batch + 2).unwrap();
    let got = engine
        .forward_backward(&ours, &x, c.as_ref(), &eps, &weights)
        .unwrap();
    let case = format!(
        "{} {} {:?} K={} labels {:?} tied {} {dtype:?}",
        config.structure,
        config.conv,
        config.pool,
        config.k,
        config.labels,
        config.tie_decoder_convs
    );
    // Mean-type poolings and sampling leave level 0 through a sparse operator: the engine then
    // runs it renumbered, so these comparisons check the renumbering too.
    let renumbered = engine.engine.renumbered();
    let sparse_pool = matches!(
        config.pool,
        Pooler::Mean | Pooler::Qem | Pooler::Remesh | Pooler::Sampling
    );
    assert_eq!(renumbered, sparse_pool, "{case}: renumbered");
    assert!(
        (got.rec - loss.rec).abs() <= tol * loss.rec.abs(),
        "{case}: rec {} vs {}",
        got.rec,
        loss.rec
    );
    assert!(
        (got.kl - loss.kl).abs() <= tol * loss.kl.abs().max(1e-3),
        "{case}: kl {} vs {}",
        got.kl,
        loss.kl
    );
    let ours_grads = engine.gradients(&ours).unwrap();
    assert_eq!(ours_grads.len(), reference.trainable_vars().len());
    // The norm clipping reads (dense weights through Gram matrices) against the sum over
    // candle's gradients.
    let want_norm = reference
        .trainable_vars()
        .iter()
        .map(|(_, var)| {
            let g = values(grads.get(var.as_tensor()).unwrap());
            g.iter().map(|x| x * x).sum::<f64>()
        })
        .sum::<f64>()
        .sqrt();
    let norm = engine.grad_norm();
    assert!(
        (norm - want_norm).abs() <= tol * want_norm,
        "{case}: gradient norm {norm} vs {want_norm}"
    );
    for ((name, var), (gname, g)) in reference.trainable_vars().iter().zip(&ours_grads) {
        assert_eq!(name, gname);
        let want = values(grads.get(var.as_tensor()).unwrap());
        let d = rel_diff(&values(g), &want, 1e-6);
        assert!(d <= tol, "{case}: d{name} differs by {d:e} (relative)");
        assert!(want.iter().any(|v| *v != 0.0), "{case}: d{name} is zero");
    }
    for ((name, a), (_, b)) in reference.state_vars().iter().zip(ours.state_vars()) {
        let d = rel_diff(&values(b.as_tensor()), &values(a.as_tensor()), 1.0);
        assert!(d <= tol, "{case}: running {name} differs by {d:e}");
    }
}

#[test]
fn loss_gradients_and_running_stats_equal_candle_autograd_in_f64() {
    let mut configs = Vec::new();
    // Every pooling, graph and remesh included.
    assert!(Pooler::ALL.contains(&Pooler::Graph) && Pooler::ALL.contains(&Pooler::Remesh));
    for structure in ["CCPC", "CPCPC"] {
        for pool in Pooler::ALL {
            configs.push(ModelConfig {
                structure: structure.parse().unwrap(),
                pool,
                channels: 5,
                latent: 6,
                ..Default::default()
            });
        }
    }
    // Spatial convolutions (the kernel with K = 2 on D⁻¹A, two weight variables), pooled and
    // not (the paper's "Only Spatial Conv." column).
    for pool in [Pooler::Mean, Pooler::None] {
        configs.push(ModelConfig {
            conv: ConvKind::Spatial,
            pool,
            channels: 5,
            latent: 6,
            ..Default::default()
        });
    }
    for k in [1, 2, 4] {
        configs.push(ModelConfig {
            k,
            channels: 4,
            latent: 5,
            ..Default::default()
        });
    }
    // The authors' variant (tanh on the last encoder convolution) and no batch norm.
    configs.push(ModelConfig {
        last_encoder_linear: false,
        latent: 5,
        ..Default::default()
    });
    configs.push(ModelConfig {
        batch_norm: false,
        structure: "CPC".parse().unwrap(),
        latent: 5,
        ..Default::default()
    });
    // Tied decoder convolutions (the adjoints of the encoder's, on the transposed operators;
    // the encoder's weights get both gradients), spectral and spatial.
    for (conv, structure) in [(ConvKind::Spectral, "CPCPC"), (ConvKind::Spatial, "CCPC")] {
        configs.push(ModelConfig {
            conv,
            structure: structure.parse().unwrap(),
            tie_decoder_convs: true,
            channels: 5,
            latent: 6,
            ..Default::default()
        });
    }
    // A conditional model (labels into both heads and the decoder's dense layer).
    let names = ["gallop", "trot", "pose"].map(String::from);
    configs.push(
        ModelConfig {
            channels: 5,
            latent: 6,
            ..Default::default()
        }
        .conditional_on(&names),
    );
    for config in &configs {
        compare_step(config, DType::F64, 3, 1e-10);
    }
    // A batch that fills the 8-lane sums of the batch norms twice and leaves a tail.
    compare_step(&configs[0], DType::F64, 19, 1e-10);
}

#[test]
fn f32_step_is_close_to_candle() {
    for conv in [ConvKind::Spectral, ConvKind::Spatial] {
        let config = ModelConfig {
            conv,
            latent: 16,
            ..Default::default()
        };
        compare_step(&config, DType::F32, 4, 2e-3);
    }
}

#[test]
fn inference_error_equals_candle_and_leaves_the_step_alone() {
    let weights = LossWeights::default();
    for (pool, dtype, tol) in Pooler::ALL.iter().map(|&p| (p, DType::F64, 1e-10)).chain([(
        Pooler::Mean,
        DType::F32,
        1e-5,
    )]) {
        let config = ModelConfig {
            pool,
            channels: 5,
            latent: 6,
            ..Default::default()
        };
        let (model, _) = models(&config, dtype);
        let mut engine = EngineExecutor::new(&model, 5).unwrap();
        let mut adam = Adam::new(model.trainable_vars(), 1e-2).unwrap();
        // A few steps, so that the running statistics are neither 0/1 nor a batch's own.
        for seed in 0..3 {
            let (x, eps) = inputs(&model, 5, seed);
            engine
                .forward_backward(&model, &x, None, &eps, &weights)
                .unwrap();
            engine.apply_adam(&mut adam, weights.l2).unwrap();
        }
        let (x, eps) = inputs(&model, 4, 9);
        engine
            .forward_backward(&model, &x, None, &eps, &weights)
            .unwrap();
        let before = engine.gradients(&model).unwrap();
        // Another batch size than the step's, and one mesh alone (batch statistics would be 0).
        for batch in [3, 1] {
            let (x, _) = inputs(&model, batch, 11);
            let want = model.rec_error(&x, None, &weights).unwrap();
            let got = engine
                .rec_error(&model, Batch { x: &x, c: None }, &weights)
                .unwrap();
            assert!(
                (got - want).abs() <= tol * want.abs(),
                "{pool:?} {dtype:?} B={batch}: {got} vs {want}"
            );
            // μ, σ, decoding and reconstruction: the applications' entry points.
            let case = format!("{pool:?} {dtype:?} B={batch}");
            let close = |got: &Tensor, want: &Tensor, what: &str| {
                assert_eq!(got.dims(), want.dims(), "{case}: {what}");
                let d = rel_diff(&values(got), &values(want), 1e-3);
                assert!(d <= tol, "{case}: {what} differs by {d:e}");
            };
            let want = model.encode(&x, None, Mode::Eval).unwrap();
            let (mu, sigma) = engine.encode(&model, Batch { x: &x, c: None }).unwrap();
            close(&mu, &want.mu, "μ");
            close(&sigma, &want.sigma, "σ");
            let z = (&want.mu + 0.5).unwrap();
            let decoded = engine.decode(&model, Batch { x: &z, c: None }).unwrap();
            close(
                &decoded,
                &model.decode(&z, None, Mode::Eval).unwrap(),
                "decode",
            );
            let rec = engine
                .reconstruct(&model, Batch { x: &x, c: None })
                .unwrap();
            close(&rec, &model.reconstruct(&x, None).unwrap(), "reconstruct");
        }
        for ((name, a), (_, b)) in before.iter().zip(&engine.gradients(&model).unwrap()) {
            assert_eq!(values(a), values(b), "{pool:?}: gradient of {name} changed");
        }
    }
}

/// Runs `steps` Adam steps on one path; returns the weights.
fn train(config: &ModelConfig, engine: bool, steps: usize) -> Vec<Vec<f64>> {
    train_clipped(config, engine, steps, 0.0)
}

fn train_clipped(config: &ModelConfig, engine: bool, steps: usize, clip: f64) -> Vec<Vec<f64>> {
    let (model, _) = models(config, DType::F64);
    let weights = LossWeights::default();
    let mut adam = Adam::new(model.trainable_vars(), 1e-3).unwrap();
    adam.set_grad_clip(clip).unwrap();
    let mut e = engine.then(|| EngineExecutor::new(&model, 4).unwrap());
    for step in 0..steps {
        // The last batch is smaller, as at the end of an epoch.
        let batch = if step + 1 == steps { 3 } else { 4 };
        let (x, eps) = inputs(&model, batch, 10 + step as u64);
        match e.as_mut() {
            Some(e) => {
                e.forward_backward(&model, &x, None, &eps, &weights)
                    .unwrap();
                e.apply_adam(&mut adam, weights.l2).unwrap();
            }
            None => {
                let loss = model.training_loss(&x, None, &eps, &weights).unwrap();
                let grads = model.backward(&loss.total).unwrap();
                adam.step_with_l2(&grads, weights.l2).unwrap();
            }
        }
    }
    let mut out: Vec<Vec<f64>> = model
        .trainable_vars()
        .iter()
        .map(|(_, v)| values(v.as_tensor()))
        .collect();
    out.extend(
        model
            .state_vars()
            .iter()
            .map(|(_, v)| values(v.as_tensor())),
    );
    out
}

#[test]
fn training_steps_match_candle_and_repeat_bit_for_bit_on_any_thread_count() {
    // Max-type poolings route gradients through recorded selections; graph pooling's overlap
    // makes the backward pass sum several of them per vertex.
    for pool in [Pooler::Max, Pooler::Graph] {
        let config = ModelConfig {
            structure: "CPCPC".parse().unwrap(),
            pool,
            channels: 4,
            latent: 6,
            ..Default::default()
        };
        let reference = train(&config, false, 4);
        let ours = train(&config, true, 4);
        for (a, b) in ours.iter().zip(&reference) {
            assert!(rel_diff(a, b, 1e-3) < 1e-9, "{pool}");
        }
        let threads = |n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
        };
        let one = threads(1).install(|| train(&config, true, 4));
        let three = threads(3).install(|| train(&config, true, 4));
        assert_eq!(one, three, "{pool}");
        assert_eq!(one, ours, "{pool}");
    }
}

/// Gradient clipping: the engine (norm from Gram matrices) and candle (norm from the formed
/// gradients) clip the same steps by the same factors, and clipping changed the run.
#[test]
fn clipped_training_steps_match_candle() {
    let config = ModelConfig {
        structure: "CPCPC".parse().unwrap(),
        pool: Pooler::Max,
        channels: 4,
        latent: 6,
        ..Default::default()
    };
    // A factor of 1 clips every step whose gradient exceeds the running mean, after the
    // 20 steps of the mean's warm-up.
    let steps = 26;
    let reference = train_clipped(&config, false, steps, 1.0);
    let ours = train_clipped(&config, true, steps, 1.0);
    for (a, b) in ours.iter().zip(&reference) {
        assert!(rel_diff(a, b, 1e-3) < 1e-9);
    }
    let unclipped = train(&config, true, steps);
    let moved = ours
        .iter()
        .zip(&unclipped)
        .any(|(a, b)| rel_diff(a, b, 1e-3) > 1e-9);
    assert!(moved, "no step was clipped");
}

#[test]
fn unsupported_models_are_declined_and_bad_inputs_are_errors() {
    let wide = ModelConfig {
        k: 9,
        latent: 4,
        ..Default::default()
    };
    let (model, _) = models(&wide, DType::F32);
    assert!(
        EngineExecutor::unsupported(&model)
            .unwrap()
            .contains("K = 9")
    );
    let err = EngineExecutor::new(&model, 2).unwrap_err().to_string();
    assert!(
        err.contains("does not cover") && err.contains("K = 9"),
        "{err}"
    );

    // Labels come exactly with a conditional model.
    let names = ["a", "b"].map(String::from);
    let conditional = ModelConfig {
        latent: 4,
        ..Default::default()
    }
    .conditional_on(&names);
    let (model, _) = models(&conditional, DType::F64);
    let mut engine = EngineExecutor::new(&model, 2).unwrap();
    let (x, eps) = inputs(&model, 2, 1);
    let w = LossWeights::default();
    let step = |engine: &mut EngineExecutor, x: &Tensor, c: Option<&Tensor>, eps: &Tensor| {
        engine
            .forward_backward(&model, x, c, eps, &w)
            .map_err(|e| e.to_string())
    };
    let err = step(&mut engine, &x, None, &eps).unwrap_err();
    assert!(err.contains("give each mesh's label"), "{err}");
    let c = model.one_hot(&["a"]).unwrap();
    let err = step(&mut engine, &x, Some(&c), &eps).unwrap_err();
    assert!(err.contains("[2, 2]"), "{err}");
    let c = model.one_hot(&["a", "b"]).unwrap();
    assert!(step(&mut engine, &x, Some(&c), &eps).is_ok());

    let config = ModelConfig {
        latent: 4,
        ..Default::default()
    };
    let (model, _) = models(&config, DType::F64);
    assert!(EngineExecutor::new(&model, 0).is_err());
    let mut engine = EngineExecutor::new(&model, 2).unwrap();
    let mut adam = Adam::new(model.trainable_vars(), 1e-3).unwrap();
    assert!(engine.apply_adam(&mut adam, 1.0).is_err(), "no step yet");
    let step = |engine: &mut EngineExecutor, x: &Tensor, eps: &Tensor| {
        engine
            .forward_backward(&model, x, None, eps, &w)
            .map_err(|e| e.to_string())
    };
    let (x, eps) = inputs(&model, 3, 1);
    let err = step(&mut engine, &x, &eps).unwrap_err();
    assert!(err.contains("at most 2"), "{err}");
    let (x, eps) = inputs(&model, 2, 1);
    let short = x.narrow(1, 0, 10).unwrap();
    assert!(step(&mut engine, &short, &eps).is_err());
    let wrong = x.to_dtype(DType::F32).unwrap();
    assert!(step(&mut engine, &wrong, &eps).is_err());
    // The model still decodes (the engine left its weights usable).
    engine.forward_backward(&model, &x, None, &eps, &w).unwrap();
    assert!(model.decode(&eps, None, Mode::Eval).is_ok());
}

#[test]
fn conditional_inference_equals_candle_and_bad_latents_are_errors() {
    let names = ["gallop", "trot"].map(String::from);
    let config = ModelConfig {
        channels: 5,
        latent: 6,
        ..Default::default()
    }
    .conditional_on(&names);
    let (model, twin) = models(&config, DType::F64);
    // Non-zero label weights (they start at zero) in the model the two paths share.
    let _ = labels(&model, &twin, 1);
    let mut engine = EngineExecutor::new(&model, 4).unwrap();
    let (x, _) = inputs(&model, 3, 5);
    let c = model.one_hot(&["trot", "gallop", "trot"]).unwrap();
    let want = model.encode(&x, Some(&c), Mode::Eval).unwrap();
    let (mu, _) = engine.encode(&model, Batch { x: &x, c: Some(&c) }).unwrap();
    assert!(rel_diff(&values(&mu), &values(&want.mu), 1e-3) < 1e-10);
    let rec = engine
        .reconstruct(&model, Batch { x: &x, c: Some(&c) })
        .unwrap();
    let want = model.reconstruct(&x, Some(&c)).unwrap();
    assert!(rel_diff(&values(&rec), &values(&want), 1e-3) < 1e-10);
    // A blend of labels decodes as candle does too.
    let blend = Tensor::from_vec(vec![4.0, 4.0, 8.0, 0.0, 0.0, 8.0], (3, 2), &Device::Cpu).unwrap();
    let z = (&mu * 0.5).unwrap();
    let blended = Batch {
        x: &z,
        c: Some(&blend),
    };
    let got = engine.decode(&model, blended).unwrap();
    let want = model.decode(&z, Some(&blend), Mode::Eval).unwrap();
    assert!(rel_diff(&values(&got), &values(&want), 1e-3) < 1e-10);

    let err = engine
        .decode(&model, Batch { x: &z, c: None })
        .unwrap_err()
        .to_string();
    assert!(err.contains("label"), "{err}");
    let wide = Tensor::zeros((5, 6), DType::F64, &Device::Cpu).unwrap();
    let too_wide = Batch {
        x: &wide,
        c: Some(&blend),
    };
    let err = engine.decode(&model, too_wide).unwrap_err();
    assert!(err.to_string().contains("[1 ..= 4, 6]"), "{err}");
}
