//! The network's variables: the one place their names, shapes and starting values are written.
//!
//! Names: `enc.conv{i}.{weight | w_self, w_nb}`, `enc.bn{i}.{gamma, beta}`, `enc.mu.{weight,
//! bias}`, `enc.sigma.{weight, bias}`, `dec.fc.bias`, `dec.conv{i}.…`, `dec.bn{i}.…`, where
//! decoder layer i mirrors encoder convolution i; a conditional model adds
//! `enc.mu.label_weight`, `enc.sigma.label_weight` and `dec.fc.label_weight`; state (not
//! trained): `{enc,dec}.bn{i}.{running_mean, running_var}`.
//!
//! Executors never spell a name: the [`super::plan::NetPlan`] hands them ids ([`ParamId`],
//! [`StateId`]), positions in the name-sorted lists of trained and state variables. Sorted, so
//! that weights are drawn in name order from one generator (a seed fixes every weight) and the
//! optimiser sees the variables in the same order whatever built them.

use super::config::ConvKind;

/// A trained variable: its position in [`super::plan::NetPlan::params`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ParamId(pub usize);

/// A state variable (batch norm's running statistics): its position in
/// [`super::plan::NetPlan::state`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct StateId(pub usize);

/// How a variable starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Init {
    /// N(0, init_std²), drawn from the model's generator.
    Normal,
    Zeros,
    Ones,
    /// U(−bound, bound), drawn from the model's generator (Glorot: √(6 / (fan_in + fan_out))).
    Uniform(f64),
}

/// One variable to create.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct VarPlan {
    pub name: String,
    pub shape: Vec<usize>,
    pub init: Init,
    /// A bias in the paper's parameter count (biases, batch norm's γ and β).
    pub bias: bool,
}

impl VarPlan {
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }
}

/// The label weights' names, into μ, σ and the decoder's dense layer, in that order.
pub(crate) const LABEL_NAMES: [&str; 3] = [
    "enc.mu.label_weight",
    "enc.sigma.label_weight",
    "dec.fc.label_weight",
];

/// Which side of the network a layer is on (the names' prefix).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Side {
    Encoder,
    Decoder,
}

impl Side {
    fn prefix(self) -> &'static str {
        match self {
            Self::Encoder => "enc",
            Self::Decoder => "dec",
        }
    }
}

/// A trained variable being planned, before the lists are sorted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ParamHandle(usize);

/// A state variable being planned, before the lists are sorted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct StateHandle(usize);

/// A convolution's weights being planned.
#[derive(Debug, Clone, Copy)]
pub(crate) enum ConvHandles {
    Cheb(ParamHandle),
    /// Self and neighbour weights.
    Spatial(ParamHandle, ParamHandle),
}

/// The variables collected while the layer list is built; [`VarList::finish`] sorts them and
/// turns handles into ids.
#[derive(Debug, Default)]
pub(crate) struct VarList {
    params: Vec<VarPlan>,
    state: Vec<VarPlan>,
}

impl VarList {
    fn param(&mut self, name: String, shape: Vec<usize>, init: Init) -> ParamHandle {
        let bias = name.ends_with(".bias") || name.ends_with(".gamma") || name.ends_with(".beta");
        self.params.push(VarPlan {
            name,
            shape,
            init,
            bias,
        });
        ParamHandle(self.params.len() - 1)
    }

    fn state(&mut self, name: String, shape: Vec<usize>, init: Init) -> StateHandle {
        self.state.push(VarPlan {
            name,
            shape,
            init,
            bias: false,
        });
        StateHandle(self.state.len() - 1)
    }

    /// A trained weight drawn from N(0, init_std²).
    pub fn weight(&mut self, name: &str, shape: Vec<usize>) -> ParamHandle {
        self.param(name.to_owned(), shape, Init::Normal)
    }

    /// A trained weight drawn Glorot-uniform for a layer of `fan_in` inputs and `fan_out`
    /// outputs.
    pub fn glorot_weight(
        &mut self,
        name: &str,
        shape: Vec<usize>,
        fan_in: usize,
        fan_out: usize,
    ) -> ParamHandle {
        let bound = (6.0 / (fan_in + fan_out).max(1) as f64).sqrt();
        self.param(name.to_owned(), shape, Init::Uniform(bound))
    }

    /// A trained weight starting at zero (a label weight: see the conditional model).
    pub fn zero_weight(&mut self, name: &str, shape: Vec<usize>) -> ParamHandle {
        self.param(name.to_owned(), shape, Init::Zeros)
    }

    /// A trained bias starting at zero.
    pub fn bias(&mut self, name: &str, len: usize) -> ParamHandle {
        self.param(name.to_owned(), vec![len], Init::Zeros)
    }

    /// A convolution's weights: one `[C_in·K, C_out]` for Chebyshev, two `[C_in, C_out]`
    /// (self, neighbours) for spatial convolutions.
    pub fn conv(
        &mut self,
        side: Side,
        index: usize,
        conv: ConvKind,
        shape: Vec<usize>,
    ) -> ConvHandles {
        let p = side.prefix();
        let mut w =
            |v: &str| self.param(format!("{p}.conv{index}.{v}"), shape.clone(), Init::Normal);
        match conv {
            ConvKind::Spectral => ConvHandles::Cheb(w("weight")),
            ConvKind::Spatial => ConvHandles::Spatial(w("w_self"), w("w_nb")),
        }
    }

    /// A batch norm's γ and β (trained), and its running mean and variance (state).
    pub fn batch_norm(
        &mut self,
        side: Side,
        index: usize,
        channels: usize,
    ) -> ([ParamHandle; 2], [StateHandle; 2]) {
        let name = |v: &str| format!("{}.bn{index}.{v}", side.prefix());
        let c = vec![channels];
        (
            [
                self.param(name("gamma"), c.clone(), Init::Ones),
                self.param(name("beta"), c.clone(), Init::Zeros),
            ],
            [
                self.state(name("running_mean"), c.clone(), Init::Zeros),
                self.state(name("running_var"), c, Init::Ones),
            ],
        )
    }

    /// The trained and the state variables, each sorted by name, and the map from handles to
    /// positions in them.
    pub fn finish(self) -> (Vec<VarPlan>, Vec<VarPlan>, Ids) {
        let (params, param_slots) = sorted(self.params);
        let (state, state_slots) = sorted(self.state);
        (
            params,
            state,
            Ids {
                params: param_slots,
                state: state_slots,
            },
        )
    }
}

/// The list sorted by name, and each original entry's position in it.
fn sorted(list: Vec<VarPlan>) -> (Vec<VarPlan>, Vec<usize>) {
    let mut order: Vec<usize> = (0..list.len()).collect();
    order.sort_by(|&a, &b| list[a].name.cmp(&list[b].name));
    let mut slot = vec![0; list.len()];
    for (pos, &i) in order.iter().enumerate() {
        slot[i] = pos;
    }
    let mut list: Vec<Option<VarPlan>> = list.into_iter().map(Some).collect();
    let out = order.iter().filter_map(|&i| list[i].take()).collect();
    (out, slot)
}

/// Handles → ids, once the lists are sorted.
#[derive(Debug)]
pub(crate) struct Ids {
    params: Vec<usize>,
    state: Vec<usize>,
}

impl Ids {
    pub fn param(&self, h: ParamHandle) -> ParamId {
        ParamId(self.params[h.0])
    }

    pub fn state(&self, h: StateHandle) -> StateId {
        StateId(self.state[h.0])
    }
}
