//! The plan names each variable once, sorted, and its steps and heads point at the right ones.

use super::*;
use crate::net::params::param_count;
use crate::net::vars::Init;
use mesh_hierarchy::Pooler;

fn plan_of(config: &ModelConfig) -> NetPlan {
    let sphere = qem_simplify::shapes::icosphere(2);
    let h = Hierarchy::build(&sphere, &config.hierarchy_config()).unwrap();
    NetPlan::new(config, &h).unwrap()
}

fn name(plan: &NetPlan, id: ParamId) -> &str {
    &plan.params[id.0].name
}

fn convs(steps: &[Step]) -> Vec<&ConvStep> {
    steps
        .iter()
        .filter_map(|s| match s {
            Step::Conv(c) => Some(c),
            Step::Pool(_) => None,
        })
        .collect()
}

#[test]
fn variables_are_sorted_and_every_id_names_its_own() {
    let config = ModelConfig {
        structure: "CPCPC".parse().unwrap(),
        channels: 4,
        latent: 3,
        ..Default::default()
    };
    let plan = plan_of(&config);
    for list in [&plan.params, &plan.state] {
        assert!(list.windows(2).all(|w| w[0].name < w[1].name));
    }
    let enc = convs(&plan.encoder);
    let dec = convs(&plan.decoder);
    assert_eq!(enc.len(), 3);
    assert_eq!(dec.len(), 3);
    for (side, steps) in [("enc", &enc), ("dec", &dec)] {
        for c in steps.iter() {
            let i = c.spec.index;
            let ConvVars::Cheb(w) = c.weights else {
                panic!("{side} conv {i} is not a Chebyshev convolution");
            };
            assert_eq!(name(&plan, w), format!("{side}.conv{i}.weight"));
            assert_eq!(plan.params[w.0].shape, [c.spec.c_in * 3, c.spec.c_out]);
            if let Some(bn) = c.bn {
                assert_eq!(name(&plan, bn.gamma), format!("{side}.bn{i}.gamma"));
                assert_eq!(name(&plan, bn.beta), format!("{side}.bn{i}.beta"));
                assert_eq!(
                    plan.state[bn.running_var.0].name,
                    format!("{side}.bn{i}.running_var")
                );
                assert_eq!(plan.state[bn.running_var.0].init, Init::Ones);
                assert!(plan.params[bn.gamma.0].bias);
            }
        }
    }
    // The decoder runs its convolutions mirrored: the output convolution (index 0) last.
    assert_eq!(
        dec.iter().map(|c| c.spec.index).collect::<Vec<_>>(),
        [2, 1, 0]
    );
    let h = plan.heads;
    assert_eq!(name(&plan, h.w_mu), "enc.mu.weight");
    assert_eq!(name(&plan, h.b_sigma), "enc.sigma.bias");
    assert_eq!(name(&plan, h.b_dec), "dec.fc.bias");
    assert_eq!(plan.flat_width(), plan.levels[2].vertices * config.channels);
    assert!(h.labels.is_none());
    // Every trained variable is used exactly once by a step or a head.
    let mut used: Vec<usize> = [h.w_mu, h.b_mu, h.w_sigma, h.b_sigma, h.b_dec]
        .iter()
        .map(|id| id.0)
        .collect();
    for c in enc.iter().chain(&dec) {
        if let ConvVars::Cheb(w) = c.weights {
            used.push(w.0);
        }
        if let Some(bn) = c.bn {
            used.extend([bn.gamma.0, bn.beta.0]);
        }
    }
    used.sort();
    assert_eq!(used, (0..plan.params.len()).collect::<Vec<_>>());
    // The paper's count, from the formula, is the plan's.
    let (mut with, mut without) = (0, 0);
    for p in &plan.params {
        with += p.len();
        without += if p.bias { 0 } else { p.len() };
    }
    let want = param_count(&config, &plan.vertex_counts());
    assert_eq!((with, without), (want.with_biases, want.without_biases));
}

#[test]
fn poolings_carry_their_matrix_and_mode_and_decoders_depool() {
    let config = ModelConfig {
        structure: "CPCPC".parse().unwrap(),
        pool: Pooler::Max,
        ..Default::default()
    };
    let plan = plan_of(&config);
    let counts = plan.vertex_counts();
    let pools = |steps: &[Step]| -> Vec<PoolStep> {
        steps
            .iter()
            .filter_map(|s| match s {
                Step::Pool(p) => Some(p.clone()),
                Step::Conv(_) => None,
            })
            .collect()
    };
    let (down, up) = (pools(&plan.encoder), pools(&plan.decoder));
    assert_eq!(
        down.iter().map(|p| (p.from, p.to)).collect::<Vec<_>>(),
        [(0, 1), (1, 2)]
    );
    assert_eq!(
        up.iter().map(|p| (p.from, p.to)).collect::<Vec<_>>(),
        [(2, 1), (1, 0)]
    );
    for p in down.iter().chain(&up) {
        assert_eq!(p.mode, PoolMode::SignedMax);
        assert_eq!(p.is_depool(), p.to < p.from);
        // `to × from`: pooling matrices are coarse × fine, de-pooling ones fine × coarse.
        assert_eq!(
            (p.matrix.rows(), p.matrix.cols()),
            (counts[p.to], counts[p.from])
        );
    }
    assert_eq!(plan.operators.len(), 3);
    assert_eq!(plan.first_pool().map(|p| p.from), Some(0));
}

#[test]
fn without_pooling_every_level_shares_the_template_operator() {
    let config = ModelConfig {
        pool: Pooler::None,
        ..Default::default()
    };
    let plan = plan_of(&config);
    assert_eq!(plan.operators.len(), 1);
    assert!(plan.levels.iter().all(|l| l.operator == 0));
    assert_eq!(plan.first_pool().map(|p| p.mode), Some(PoolMode::Identity));
}

#[test]
fn tied_spatial_and_conditional_networks_plan_their_own_variables() {
    let tied = plan_of(&ModelConfig {
        conv: ConvKind::Spatial,
        tie_decoder_convs: true,
        ..Default::default()
    });
    assert!(
        convs(&tied.decoder)
            .iter()
            .all(|c| c.weights == ConvVars::Tied)
    );
    assert!(!tied.params.iter().any(|p| p.name.starts_with("dec.conv")));
    let ConvVars::Spatial { w_self, w_nb } = convs(&tied.encoder)[0].weights else {
        panic!("a spatial convolution has two weights");
    };
    assert_eq!(name(&tied, w_self), "enc.conv0.w_self");
    assert_eq!(name(&tied, w_nb), "enc.conv0.w_nb");

    let labels = vec!["a".to_owned(), "b".to_owned()];
    let cond = plan_of(&ModelConfig::default().conditional_on(&labels));
    let l = cond
        .heads
        .labels
        .expect("a conditional model has label weights");
    assert_eq!(name(&cond, l.dec), "dec.fc.label_weight");
    assert_eq!(cond.params[l.dec.0].shape, [2, cond.flat_width()]);
    assert_eq!(cond.params[l.mu.0].init, Init::Zeros);
    assert!(!cond.params[l.sigma.0].bias);
}
