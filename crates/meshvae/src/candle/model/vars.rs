//! The model's variables: their names, shapes and initialisation, created in sorted-name order
//! from one [`Rng`] so that a seed fixes every weight.
//!
//! Names: `enc.conv{i}.{weight | w_self, w_nb}`, `enc.bn{i}.{gamma, beta}`, `enc.mu.{weight,
//! bias}`, `enc.sigma.{weight, bias}`, `dec.fc.bias`, `dec.conv{i}.…`, `dec.bn{i}.…`, where
//! decoder layer i mirrors encoder convolution i; state (not trained):
//! `{enc,dec}.bn{i}.{running_mean, running_var}`.

use crate::error::Result;
use crate::net::config::{ConvKind, ConvSpec, ModelConfig};
use crate::numerics::rng::Rng;
use candle_core::{DType, Device, Tensor, Var};
use std::collections::BTreeMap;

/// How a variable starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Init {
    /// N(0, init_std²), drawn from the model's generator.
    Normal,
    Zeros,
    Ones,
}

/// One variable to create.
#[derive(Debug, Clone)]
pub(crate) struct VarPlan {
    pub name: String,
    pub shape: Vec<usize>,
    pub init: Init,
    pub trainable: bool,
}

/// Whether a trainable variable is a bias in the paper's parameter count (biases, BN γ and β).
pub(crate) fn is_bias(name: &str) -> bool {
    name.ends_with(".bias") || name.ends_with(".gamma") || name.ends_with(".beta")
}

/// Names of a convolution's weight variables (`side` = `enc` or `dec`).
pub(crate) fn conv_weight_names(side: &str, conv: ConvKind, index: usize) -> Vec<String> {
    match conv {
        ConvKind::Spectral => vec![format!("{side}.conv{index}.weight")],
        ConvKind::Spatial => vec![
            format!("{side}.conv{index}.w_self"),
            format!("{side}.conv{index}.w_nb"),
        ],
    }
}

/// Names of a batch norm's γ, β, running mean and running variance.
pub(crate) fn bn_names(side: &str, index: usize) -> [String; 4] {
    ["gamma", "beta", "running_mean", "running_var"].map(|v| format!("{side}.bn{index}.{v}"))
}

fn conv_plan(config: &ModelConfig, side: &str, spec: &ConvSpec, out: &mut Vec<VarPlan>) {
    let weight = |name: String, shape: Vec<usize>| VarPlan {
        name,
        shape,
        init: Init::Normal,
        trainable: true,
    };
    let own_weights = side == "enc" || !config.tie_decoder_convs;
    if own_weights {
        let names = conv_weight_names(side, config.conv, spec.index);
        let shape = match config.conv {
            ConvKind::Spectral => vec![spec.c_in * config.k, spec.c_out],
            ConvKind::Spatial => vec![spec.c_in, spec.c_out],
        };
        out.extend(names.into_iter().map(|n| weight(n, shape.clone())));
    }
    if spec.batch_norm {
        let [gamma, beta, mean, var] = bn_names(side, spec.index);
        let c = vec![spec.c_out];
        for (name, init, trainable) in [
            (gamma, Init::Ones, true),
            (beta, Init::Zeros, true),
            (mean, Init::Zeros, false),
            (var, Init::Ones, false),
        ] {
            out.push(VarPlan {
                name,
                shape: c.clone(),
                init,
                trainable,
            });
        }
    }
}

/// Every variable of the network whose coarsest level has `coarse` vertices.
pub(crate) fn plan(config: &ModelConfig, coarse: usize) -> Vec<VarPlan> {
    let mut out = Vec::new();
    for spec in config.encoder_convs() {
        conv_plan(config, "enc", &spec, &mut out);
    }
    for spec in config.decoder_convs() {
        conv_plan(config, "dec", &spec, &mut out);
    }
    let flat = coarse * config.channels;
    let var = |name: &str, shape: Vec<usize>, init| VarPlan {
        name: name.to_owned(),
        shape,
        init,
        trainable: true,
    };
    out.push(var(
        "enc.mu.weight",
        vec![flat, config.latent],
        Init::Normal,
    ));
    out.push(var("enc.mu.bias", vec![config.latent], Init::Zeros));
    out.push(var(
        "enc.sigma.weight",
        vec![flat, config.latent],
        Init::Normal,
    ));
    out.push(var("enc.sigma.bias", vec![config.latent], Init::Zeros));
    out.push(var("dec.fc.bias", vec![flat], Init::Zeros));
    out
}

/// Trainable and state variables, in two maps.
pub(crate) type VarMaps = (BTreeMap<String, Var>, BTreeMap<String, Var>);

/// Creates the planned variables in sorted-name order, drawing every normal one from `rng`.
pub(crate) fn create(
    plan: &[VarPlan],
    init_std: f64,
    dtype: DType,
    device: &Device,
    rng: &mut Rng,
) -> Result<VarMaps> {
    let mut sorted: Vec<&VarPlan> = plan.iter().collect();
    sorted.sort_by(|a, b| a.name.cmp(&b.name));
    let (mut trainable, mut state) = (BTreeMap::new(), BTreeMap::new());
    for p in sorted {
        let n: usize = p.shape.iter().product();
        let values = match p.init {
            Init::Normal => rng.normals(n).into_iter().map(|x| x * init_std).collect(),
            Init::Zeros => vec![0.0; n],
            Init::Ones => vec![1.0; n],
        };
        let t = Tensor::from_vec(values, p.shape.as_slice(), device)?.to_dtype(dtype)?;
        let var = Var::from_tensor(&t)?;
        let map = if p.trainable {
            &mut trainable
        } else {
            &mut state
        };
        map.insert(p.name.clone(), var);
    }
    Ok((trainable, state))
}
