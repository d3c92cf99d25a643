//! The conditional VAE (Sohn et al. 2015, the paper's §"Conditional VAE"): a one-hot label c of
//! the model's L labels is concatenated to the flattened encoder features before both heads and
//! to z before the decoder's dense layer.
//!
//! Concatenation is a sum of two products: [h, c]·[W; W_c] = h·W + c·W_c, so each head keeps
//! its weight W for the features and gains a `[L, latent]` block W_c for the label; the decoder
//! computes [z, c]·[W_μᵀ; W_dc] = z·W_μᵀ + c·W_dc. The decoder's tie to the μ head covers only
//! the feature rows of W_μ (its transpose maps latent → features; the label rows have no
//! counterpart), so the label part of the decoder is its own `[L, V_L·C]` weight W_dc.
//!
//! The three label weights start at zero (a freshly built conditional model computes what the
//! unconditional one of the same seed does, and draws no extra random numbers, so every other
//! weight is the same too) and are trained like the others, L2 term included. The prior stays
//! N(0, I): Sohn et al.'s simple variant with p(z|c) = p(z), so the KL term is unchanged and
//! generation draws z ~ N(0, I) with the requested c.
//!
//! The label's active entry is [`LABEL_SCALE`] rather than 1. Why: Adam moves every weight by
//! about the learning rate per step whatever its gradient's size, so with a 0/1 input the label
//! offsets c·W grow by ~lr per step while z·W_μᵀ, a sum over the latent size, changes many
//! times faster; the class information then goes through z (the encoder separates the labels
//! in latent space) and z ~ N(0, I) decodes shapes of either label whatever c says. Measured
//! on the synthetic bend/twist set (docs/benchmarks.md, "Conditional VAE"): with 1, 60 % / 85 %
//! of the samples nearest to a mesh of their label; with 8, 100 % / 80 %, the same training.
//!
//! Variables: `enc.mu.label_weight`, `enc.sigma.label_weight` `[L, latent]`,
//! `dec.fc.label_weight` `[L, V_L·C]` (weights, not biases, in the parameter count).

use crate::error::{Result, VaeError};
use candle_core::{DType, Device, Tensor};

/// The value of a one-hot label's active entry (see the module documentation).
pub const LABEL_SCALE: f32 = 8.0;

/// The label weights of a conditional model.
#[derive(Debug, Clone)]
pub(crate) struct LabelWeights {
    /// `[L, latent]`: c's contribution to μ's pre-activation.
    pub mu: Tensor,
    /// `[L, latent]`: c's contribution to σ's pre-activation.
    pub sigma: Tensor,
    /// `[L, V_L·C]`: c's contribution to the decoder's dense layer.
    pub dec: Tensor,
}

/// One-hot rows `[B, L]` (active entry [`LABEL_SCALE`]) for `labels`, each one of `classes`.
///
/// Errors: a label not in `classes`, naming it and listing the known ones.
pub(crate) fn one_hot<S: AsRef<str>>(
    classes: &[String],
    labels: &[S],
    dtype: DType,
    device: &Device,
) -> Result<Tensor> {
    let l = classes.len();
    let mut data = vec![0f32; labels.len() * l];
    for (row, label) in labels.iter().enumerate() {
        let label = label.as_ref();
        let k = classes
            .iter()
            .position(|c| c == label)
            .ok_or_else(|| unknown_label(classes, label))?;
        data[row * l + k] = LABEL_SCALE;
    }
    Ok(Tensor::from_vec(data, (labels.len(), l), device)?.to_dtype(dtype)?)
}

/// The labels of the meshes `ids` (indices into `labels`).
///
/// Errors: an index out of range.
pub(crate) fn pick<'a>(labels: &'a [String], ids: &[usize]) -> Result<Vec<&'a String>> {
    ids.iter()
        .map(|&i| {
            labels.get(i).ok_or_else(|| {
                VaeError::argument(
                    "mesh index",
                    format!("{i} is out of range ({} meshes)", labels.len()),
                )
            })
        })
        .collect()
}

/// The error for a label the model does not know.
pub(crate) fn unknown_label(classes: &[String], label: &str) -> VaeError {
    if classes.is_empty() {
        return VaeError::argument(
            "label",
            format!("{label:?}: the model is not conditional (it was trained without labels)"),
        );
    }
    VaeError::argument(
        "label",
        format!(
            "{label:?} is not a label of this model; it knows {}",
            classes.join(", ")
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::super::MeshVae;
    use crate::candle::batch_norm::Mode;
    use crate::net::config::ModelConfig;
    use crate::net::loss_weights::LossWeights;
    use crate::numerics::rng::Rng;
    use candle_core::{DType, Device, Tensor};
    use mesh_hierarchy::Hierarchy;

    fn labels() -> Vec<String> {
        ["gallop", "pose", "trot"].map(String::from).to_vec()
    }

    fn config(conditional: bool) -> ModelConfig {
        let c = ModelConfig {
            structure: "CPC".parse().unwrap(),
            latent: 5,
            channels: 4,
            init_std: 0.3,
            ..Default::default()
        };
        if conditional {
            c.conditional_on(&labels())
        } else {
            c
        }
    }

    fn hierarchy(config: &ModelConfig) -> Hierarchy {
        let sphere = qem_simplify::shapes::icosphere(1);
        Hierarchy::build(&sphere, &config.hierarchy_config()).unwrap()
    }

    fn random(shape: &[usize], seed: u64) -> Tensor {
        let n = shape.iter().product();
        Tensor::from_vec(Rng::new(seed).normals(n), shape, &Device::Cpu).unwrap()
    }

    fn rows(t: &Tensor) -> Vec<Vec<f64>> {
        t.to_vec2().unwrap()
    }

    /// A conditional model, its unconditional twin of the same seed, and random label weights.
    fn pair() -> (MeshVae, MeshVae) {
        let (cc, pc) = (config(true), config(false));
        let h = hierarchy(&cc);
        let cond = MeshVae::with_dtype(&cc, &h, &Device::Cpu, DType::F64, 7).unwrap();
        let plain = MeshVae::with_dtype(&pc, &h, &Device::Cpu, DType::F64, 7).unwrap();
        (cond, plain)
    }

    fn set_random_label_weights(model: &MeshVae) {
        for (k, name) in crate::net::vars::LABEL_NAMES.iter().enumerate() {
            let v = model.trainable()[*name].clone();
            v.set(&random(v.dims(), 40 + k as u64)).unwrap();
        }
    }

    #[test]
    fn label_weights_start_at_zero_and_leave_every_other_weight_as_unconditional() {
        let (cond, plain) = pair();
        let flat = cond.flat_width();
        for (name, v) in &cond.trainable() {
            match plain.trainable().get(name) {
                Some(p) => assert_eq!(
                    v.as_tensor()
                        .flatten_all()
                        .unwrap()
                        .to_vec1::<f64>()
                        .unwrap(),
                    p.as_tensor()
                        .flatten_all()
                        .unwrap()
                        .to_vec1::<f64>()
                        .unwrap(),
                    "{name}"
                ),
                None => {
                    assert!(
                        crate::net::vars::LABEL_NAMES.contains(&name.as_str()),
                        "{name}"
                    );
                    let sum: f64 = v
                        .as_tensor()
                        .abs()
                        .unwrap()
                        .sum_all()
                        .unwrap()
                        .to_scalar()
                        .unwrap();
                    assert_eq!(sum, 0.0, "{name}");
                }
            }
        }
        assert_eq!(cond.trainable().len(), plain.trainable().len() + 3);
        assert_eq!(cond.trainable()["dec.fc.label_weight"].dims(), [3, flat]);
        assert_eq!(cond.trainable()["enc.sigma.label_weight"].dims(), [3, 5]);
        // Its parameter count is the formula's.
        let counts = &cond.vertex_counts;
        assert_eq!(
            cond.param_count(),
            crate::net::params::param_count(cond.config(), counts)
        );
        assert_eq!(
            cond.param_count().without_biases,
            plain.param_count().without_biases + 3 * (2 * 5 + flat)
        );
    }

    #[test]
    fn the_label_enters_both_heads_and_the_decoder_as_a_concatenated_input() {
        let (cond, plain) = pair();
        set_random_label_weights(&cond);
        let v = cond.vertex_count();
        let x = random(&[3, v, 9], 1);
        // One-hot rows, and a blend (the concatenation is linear in c, one-hot or not).
        let c = cond.one_hot(&["pose", "gallop", "trot"]).unwrap();
        let blend = Tensor::new(&[[0.25f64, 0.75, 0.0]], &Device::Cpu).unwrap();
        let c = Tensor::cat(&[&c.narrow(0, 0, 2).unwrap(), &blend], 0).unwrap();
        let got = cond.encode(&x, Some(&c), Mode::Eval).unwrap();
        let base = plain.encode(&x, None, Mode::Eval).unwrap();
        let w = |name: &str| rows(cond.trainable()[name].as_tensor());
        let (w_mu, w_sigma, w_dec) = (
            w("enc.mu.label_weight"),
            w("enc.sigma.label_weight"),
            w("dec.fc.label_weight"),
        );
        let cs = rows(&c);
        let (mu, mu0) = (rows(&got.mu), rows(&base.mu));
        let (sigma, sigma0) = (rows(&got.sigma), rows(&base.sigma));
        for b in 0..3 {
            for j in 0..5 {
                let shift = |w: &[Vec<f64>]| (0..3).map(|k| cs[b][k] * w[k][j]).sum::<f64>();
                assert!((mu[b][j] - (mu0[b][j] + shift(&w_mu))).abs() < 1e-12);
                // σ = √(2·sigmoid(s)): recover s of the unconditional twin, add c·W_σ.
                let s0 = {
                    let q = sigma0[b][j] * sigma0[b][j] / 2.0;
                    (q / (1.0 - q)).ln()
                };
                let want = (2.0 / (1.0 + (-(s0 + shift(&w_sigma))).exp())).sqrt();
                assert!(
                    (sigma[b][j] - want).abs() < 1e-9,
                    "{} vs {want}",
                    sigma[b][j]
                );
            }
        }
        let z = random(&[3, 5], 2);
        let h = rows(&cond.decoder_fc(&z, Some(&c)).unwrap());
        let h0 = rows(&plain.decoder_fc(&z, None).unwrap());
        for b in 0..3 {
            for (p, (&got, &base)) in h[b].iter().zip(&h0[b]).enumerate() {
                let want = base + (0..3).map(|k| cs[b][k] * w_dec[k][p]).sum::<f64>();
                assert!((got - want).abs() < 1e-12);
            }
        }
        // The decoder sees the label: two labels decode one z differently.
        let z1 = random(&[1, 5], 3);
        let [a, b] = ["gallop", "pose"].map(|l| {
            let y = cond.decode(&z1, Some(&cond.one_hot(&[l]).unwrap()), Mode::Eval);
            y.unwrap().flatten_all().unwrap().to_vec1::<f64>().unwrap()
        });
        assert!(a.iter().zip(&b).any(|(p, q)| (p - q).abs() > 1e-6));
    }

    #[test]
    fn label_weight_gradients_match_finite_differences() {
        let (cond, _) = pair();
        set_random_label_weights(&cond);
        let v = cond.vertex_count();
        let x = (random(&[2, v, 9], 5) * 0.5).unwrap();
        let eps = random(&[2, 5], 6);
        let c = cond.one_hot(&["trot", "gallop"]).unwrap();
        let weights = LossWeights::default();
        let loss = |m: &MeshVae| -> f64 {
            let l = m.loss(&x, Some(&c), &eps, &weights).unwrap();
            l.total.to_scalar().unwrap()
        };
        let total = cond.loss(&x, Some(&c), &eps, &weights).unwrap().total;
        let grads = cond.backward(&total).unwrap();
        for name in crate::net::vars::LABEL_NAMES {
            let var = cond.trainable()[name].clone();
            let grad = grads.get(var.as_tensor()).unwrap();
            let grad: Vec<f64> = grad.flatten_all().unwrap().to_vec1().unwrap();
            let values: Vec<f64> = var.as_tensor().flatten_all().unwrap().to_vec1().unwrap();
            // Rows 0 and 2 (gallop, trot) are in the batch; row 1 (pose) only in the L2 term.
            let width = var.dims()[1];
            for i in [0, 1, 2 * width + 1, width + 2] {
                let h = 1e-4;
                let mut plus = values.clone();
                plus[i] += h;
                var.set(&Tensor::from_vec(plus, var.dims(), &Device::Cpu).unwrap())
                    .unwrap();
                let up = loss(&cond);
                let mut minus = values.clone();
                minus[i] -= h;
                var.set(&Tensor::from_vec(minus, var.dims(), &Device::Cpu).unwrap())
                    .unwrap();
                let down = loss(&cond);
                var.set(&Tensor::from_vec(values.clone(), var.dims(), &Device::Cpu).unwrap())
                    .unwrap();
                let fd = (up - down) / (2.0 * h);
                // Relative above 1, absolute below (as the model's own gradient check): the
                // loss is ~10³, so the central difference itself is good to ~10⁻⁶ only.
                let scale = fd.abs().max(grad[i].abs()).max(1.0);
                assert!(
                    (fd - grad[i]).abs() < 1e-5 * scale,
                    "{name}[{i}]: autodiff {} vs fd {fd}",
                    grad[i]
                );
            }
        }
    }

    #[test]
    fn labels_come_exactly_with_a_conditional_model() {
        let (cond, plain) = pair();
        let v = cond.vertex_count();
        let x = random(&[2, v, 9], 1);
        let err = cond.encode(&x, None, Mode::Eval).unwrap_err().to_string();
        assert!(
            err.contains("conditional on the labels gallop, pose, trot"),
            "{err}"
        );
        let err = cond
            .decode(&random(&[2, 5], 1), None, Mode::Eval)
            .unwrap_err()
            .to_string();
        assert!(err.contains("give each mesh's label"), "{err}");
        let c = cond.one_hot(&["pose", "pose"]).unwrap();
        let err = plain
            .encode(&x, Some(&c), Mode::Eval)
            .unwrap_err()
            .to_string();
        assert!(err.contains("not conditional"), "{err}");
        let one = cond.one_hot(&["pose"]).unwrap();
        let err = cond
            .encode(&x, Some(&one), Mode::Eval)
            .unwrap_err()
            .to_string();
        assert!(err.contains("expected [2, 3]"), "{err}");
        let err = cond.one_hot(&["canter"]).unwrap_err().to_string();
        assert!(
            err.contains("\"canter\"") && err.contains("gallop, pose, trot"),
            "{err}"
        );
        let err = plain.one_hot(&["pose"]).unwrap_err().to_string();
        assert!(err.contains("not conditional"), "{err}");
        let got = rows(&cond.one_hot(&["trot", "gallop"]).unwrap());
        let s = f64::from(super::LABEL_SCALE);
        assert_eq!(got, [[0.0, 0.0, s], [s, 0.0, 0.0]]);
    }

    #[test]
    fn conditional_weights_round_trip_and_are_refused_by_an_unconditional_model() {
        let (cond, _) = pair();
        set_random_label_weights(&cond);
        let dir = std::env::temp_dir().join(format!("meshvae-cond-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("w.safetensors");
        cond.save(&path).unwrap();
        let (mut back, mut plain) = pair();
        back.load(&path).unwrap();
        let name = "dec.fc.label_weight";
        assert_eq!(
            rows(back.trainable()[name].as_tensor()),
            rows(cond.trainable()[name].as_tensor())
        );
        let err = plain.load(&path).unwrap_err().to_string();
        assert!(err.contains("labels"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
