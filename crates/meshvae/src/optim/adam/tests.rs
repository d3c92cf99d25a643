use super::*;
use crate::numerics::rng::Rng;
use candle_core::Device;
use candle_nn::{AdamW, Optimizer, ParamsAdamW};

/// A small non-quadratic loss of two variables, so the moments differ per element.
fn loss(a: &Var, b: &Var, target: &Tensor) -> Tensor {
    let y = a.as_tensor().matmul(b.as_tensor()).unwrap().tanh().unwrap();
    (y - target).unwrap().sqr().unwrap().sum_all().unwrap()
}

fn setup(seed: u64) -> (Var, Var, Tensor) {
    let mut rng = Rng::new(seed);
    let dev = Device::Cpu;
    let a = Var::from_tensor(&rng.normal_tensor((4, 3), &dev).unwrap()).unwrap();
    let b = Var::from_tensor(&rng.normal_tensor((3, 5), &dev).unwrap()).unwrap();
    let t = rng.normal_tensor((4, 5), &dev).unwrap();
    (a, b, t)
}

fn max_diff(x: &Tensor, y: &Tensor) -> f32 {
    (x - y)
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap()
        .to_scalar()
        .unwrap()
}

#[test]
fn fifty_steps_match_candle_adamw_without_decay() {
    let (a1, b1, t) = setup(1);
    let (a2, b2, _) = setup(1);
    let mut ours = Adam::new(
        vec![("a".into(), a1.clone()), ("b".into(), b1.clone())],
        1e-3,
    )
    .unwrap();
    let params = ParamsAdamW {
        weight_decay: 0.0,
        ..Default::default()
    };
    let mut theirs = AdamW::new(vec![a2.clone(), b2.clone()], params).unwrap();
    let start = a1.as_tensor().copy().unwrap();
    for _ in 0..50 {
        ours.step(&loss(&a1, &b1, &t).backward().unwrap()).unwrap();
        theirs
            .step(&loss(&a2, &b2, &t).backward().unwrap())
            .unwrap();
    }
    assert!(max_diff(a1.as_tensor(), a2.as_tensor()) < 1e-6);
    assert!(max_diff(b1.as_tensor(), b2.as_tensor()) < 1e-6);
    // It moved: 50 steps of lr 1e-3 change the weights by up to ~0.05.
    assert!(max_diff(a1.as_tensor(), &start) > 1e-2);
    assert_eq!(ours.step_count(), 50);
}

#[test]
fn grad_store_and_slice_steps_update_alike_and_sum_the_squares() {
    // Odd sizes: the eight-lane square sum has a ragged tail.
    let mut rng = Rng::new(5);
    let dev = Device::Cpu;
    let make = |rng: &mut Rng, shape: (usize, usize)| {
        Var::from_tensor(&rng.normal_tensor(shape, &dev).unwrap()).unwrap()
    };
    let (a1, b1) = (make(&mut rng, (37, 29)), make(&mut rng, (29, 11)));
    let t = rng.normal_tensor((37, 11), &dev).unwrap();
    let copy = |v: &Var| Var::from_tensor(&v.as_tensor().copy().unwrap()).unwrap();
    let (a2, b2) = (copy(&a1), copy(&b1));
    let named = |a: &Var, b: &Var| vec![("a".to_string(), a.clone()), ("b".to_string(), b.clone())];
    let mut from_store = Adam::new(named(&a1, &b1), 1e-2).unwrap();
    let mut fused = Adam::new(named(&a2, &b2), 1e-2).unwrap();
    let l2 = 0.3;
    for _ in 0..5 {
        from_store
            .step_with_l2(&loss(&a1, &b1, &t).backward().unwrap(), l2)
            .unwrap();
        let grads = loss(&a2, &b2, &t).backward().unwrap();
        let g: Vec<Vec<f32>> = [&a2, &b2]
            .iter()
            .map(|v| {
                grads
                    .get(v.as_tensor())
                    .unwrap()
                    .flatten_all()
                    .unwrap()
                    .to_vec1()
                    .unwrap()
            })
            .collect();
        let expected: f64 = [&a2, &b2]
            .iter()
            .flat_map(|v| {
                v.as_tensor()
                    .flatten_all()
                    .unwrap()
                    .to_vec1::<f32>()
                    .unwrap()
            })
            .map(|x| 0.5 * f64::from(x) * f64::from(x))
            .sum();
        let half_sq = fused
            .step_with_slices(&[g[0].as_slice(), g[1].as_slice()], l2)
            .unwrap();
        assert!(
            (half_sq - expected).abs() <= 1e-12 * expected,
            "{half_sq} vs {expected}"
        );
    }
    for (x, y) in [(&a1, &a2), (&b1, &b2)] {
        let bits = |v: &Var| -> Vec<u32> {
            let values: Vec<f32> = v.as_tensor().flatten_all().unwrap().to_vec1().unwrap();
            values.iter().map(|f| f.to_bits()).collect()
        };
        assert_eq!(
            bits(x),
            bits(y),
            "the GradStore step differs from the slice step"
        );
    }
}

/// The first step from zero moments is θ − lr·ĝ/(|ĝ| + ε) with ĝ = g + l2·θ (the bias
/// corrections undo the decays exactly): the one update pass against the formula, in f64.
#[test]
fn first_step_is_the_sign_step_of_the_formula() {
    let dev = Device::Cpu;
    let theta0: Vec<f64> = vec![0.5, -1.25, 2.0, 0.0, -0.001, 3.5, 1e-3, -7.0, 0.25];
    let g: Vec<f64> = vec![0.1, 0.2, -0.3, 1e-9, 0.0, -2.0, 5.0, 0.01, -0.02];
    let var = Var::from_tensor(&Tensor::from_vec(theta0.clone(), 9, &dev).unwrap()).unwrap();
    let (lr, l2) = (1e-2, 0.3);
    let mut adam = Adam::new(vec![("w".to_string(), var.clone())], lr).unwrap();
    adam.step_with_slices(&[g.as_slice()], l2).unwrap();
    let eps = adam.config().eps;
    let got: Vec<f64> = var.as_tensor().to_vec1().unwrap();
    for i in 0..9 {
        let gh = g[i] + l2 * theta0[i];
        let want = theta0[i] - lr * gh / (gh.abs() + eps);
        assert!((got[i] - want).abs() <= 1e-12, "{i}: {} vs {want}", got[i]);
    }
}

/// A gradient made block by block ([`GradSource::Rows`], rows that do not divide the
/// block size, a short last block) updates exactly as the same gradient in one slice.
#[test]
fn row_sources_update_like_slices() {
    let (rows, cols) = (300usize, 70usize);
    let init: Vec<f32> = (0..rows * cols).map(|i| (i as f32 * 0.37).sin()).collect();
    let var = || Var::from_vec(init.clone(), (rows, cols), &Device::Cpu).unwrap();
    let (a, b) = (var(), var());
    let mut sliced = Adam::new(vec![("w".to_string(), a.clone())], 1e-2).unwrap();
    let mut by_rows = Adam::new(vec![("w".to_string(), b.clone())], 1e-2).unwrap();
    for step in 0..3 {
        let g: Vec<f32> = (0..rows * cols)
            .map(|i| ((i * (step + 2)) as f32 * 0.11).cos())
            .collect();
        let fill = |first: usize, out: &mut [f32]| {
            assert_eq!(out.len() % cols, 0, "not whole rows");
            out.copy_from_slice(&g[first * cols..first * cols + out.len()]);
        };
        let x = sliced.step_with_slices(&[g.as_slice()], 0.3).unwrap();
        let rows_source = GradSource::Rows {
            row_len: cols,
            fill: &fill,
        };
        let y = by_rows.step_with_sources(&[rows_source], 0.3, 1.0).unwrap();
        assert!((x - y).abs() <= 1e-12 * x, "{x} vs {y}");
    }
    let values = |v: &Var| -> Vec<f32> { v.as_tensor().flatten_all().unwrap().to_vec1().unwrap() };
    assert_eq!(values(&a), values(&b));
    let moments = |o: &Adam| -> Vec<Vec<f32>> {
        o.state_tensors().unwrap()[1..]
            .iter()
            .map(|(_, t)| t.flatten_all().unwrap().to_vec1().unwrap())
            .collect()
    };
    assert_eq!(moments(&sliced), moments(&by_rows));
    let fill = |_: usize, _: &mut [f32]| {};
    for row_len in [0, 33] {
        let bad = GradSource::Rows {
            row_len,
            fill: &fill,
        };
        let e = by_rows.step_with_sources(&[bad], 0.0, 1.0).unwrap_err();
        assert!(e.to_string().contains("rows of"), "{e}");
    }
}

#[test]
fn state_round_trip_resumes_exactly() {
    let (a, b, t) = setup(2);
    let vars = || vec![("a".to_owned(), a.clone()), ("b".to_owned(), b.clone())];
    let mut opt = Adam::new(vars(), 1e-3).unwrap();
    for _ in 0..5 {
        opt.step(&loss(&a, &b, &t).backward().unwrap()).unwrap();
    }
    let state: HashMap<String, Tensor> = opt.state_tensors().unwrap().into_iter().collect();
    let (wa, wb) = (a.as_tensor().copy().unwrap(), b.as_tensor().copy().unwrap());
    for _ in 0..5 {
        opt.step(&loss(&a, &b, &t).backward().unwrap()).unwrap();
    }
    let (ua, ub) = (a.as_tensor().copy().unwrap(), b.as_tensor().copy().unwrap());
    // Rewind the weights and restore the optimiser into a fresh one.
    a.set(&wa).unwrap();
    b.set(&wb).unwrap();
    let mut resumed = Adam::new(vars(), 1e-3).unwrap();
    resumed.load_state(&state).unwrap();
    assert_eq!(resumed.step_count(), 5);
    for _ in 0..5 {
        resumed.step(&loss(&a, &b, &t).backward().unwrap()).unwrap();
    }
    assert_eq!(max_diff(a.as_tensor(), &ua), 0.0);
    assert_eq!(max_diff(b.as_tensor(), &ub), 0.0);
}

#[test]
fn bad_state_and_config_are_typed_errors() {
    let (a, _, _) = setup(3);
    assert!(Adam::new(vec![], 0.0).is_err());
    let mut opt = Adam::new(vec![("a".into(), a.clone())], 1e-3).unwrap();
    let mut state: HashMap<String, Tensor> = opt.state_tensors().unwrap().into_iter().collect();
    state.insert(
        "adam.m.a".into(),
        Tensor::zeros((2, 2), DType::F32, &Device::Cpu).unwrap(),
    );
    let err = opt.load_state(&state).unwrap_err().to_string();
    assert!(err.contains("adam.m.a") && err.contains("shape"), "{err}");
    state.remove("adam.m.a");
    assert!(
        opt.load_state(&state)
            .unwrap_err()
            .to_string()
            .contains("no adam.m.a")
    );
}

#[test]
fn a_restart_steps_as_a_fresh_optimiser_and_survives_the_state() {
    let (a, b, t) = setup(4);
    let vars = || vec![("a".to_owned(), a.clone()), ("b".to_owned(), b.clone())];
    let mut opt = Adam::new(vars(), 1e-3).unwrap();
    for _ in 0..7 {
        opt.step(&loss(&a, &b, &t).backward().unwrap()).unwrap();
    }
    opt.restart().unwrap();
    assert_eq!(opt.step_count(), 7, "a restart keeps counting steps");
    let (wa, wb) = (a.as_tensor().copy().unwrap(), b.as_tensor().copy().unwrap());
    let state: HashMap<String, Tensor> = opt.state_tensors().unwrap().into_iter().collect();
    for _ in 0..3 {
        opt.step(&loss(&a, &b, &t).backward().unwrap()).unwrap();
    }
    let (ua, ub) = (a.as_tensor().copy().unwrap(), b.as_tensor().copy().unwrap());
    // A fresh optimiser (zero moments, bias correction from step 1) from the same weights.
    a.set(&wa).unwrap();
    b.set(&wb).unwrap();
    let mut fresh = Adam::new(vars(), 1e-3).unwrap();
    for _ in 0..3 {
        fresh.step(&loss(&a, &b, &t).backward().unwrap()).unwrap();
    }
    assert_eq!(max_diff(a.as_tensor(), &ua), 0.0);
    assert_eq!(max_diff(b.as_tensor(), &ub), 0.0);
    // The restarted state reloads into another optimiser and steps the same.
    a.set(&wa).unwrap();
    b.set(&wb).unwrap();
    let mut resumed = Adam::new(vars(), 1e-3).unwrap();
    resumed.load_state(&state).unwrap();
    for _ in 0..3 {
        resumed.step(&loss(&a, &b, &t).backward().unwrap()).unwrap();
    }
    assert_eq!(max_diff(a.as_tensor(), &ua), 0.0);
    assert_eq!(resumed.step_count(), 10);
}

/// A variable given its own rate ([`Adam::scale_lr`]) takes the formula's step at that rate,
/// on both update paths (gradient slices and candle's gradient store), and the others keep the
/// optimiser's; unknown names and non-positive scales are refused.
#[test]
fn a_scaled_variable_steps_at_its_own_rate() {
    let dev = Device::Cpu;
    let theta0: Vec<f64> = vec![0.5, -1.25, 2.0, 0.75];
    let g: Vec<f64> = vec![0.1, -0.2, 0.3, 5.0];
    let var = || Var::from_tensor(&Tensor::from_vec(theta0.clone(), 4, &dev).unwrap()).unwrap();
    let (lr, scale) = (1e-2, 0.1);
    // The first step from zero moments is θ − rate·g/(|g| + ε).
    let want = |rate: f64| -> Vec<f64> {
        (0..4)
            .map(|i| theta0[i] - rate * g[i] / (g[i].abs() + 1e-8))
            .collect()
    };
    let close = |got: &Var, want: &[f64]| {
        let got: Vec<f64> = got.as_tensor().to_vec1().unwrap();
        assert!(
            got.iter().zip(want).all(|(a, b)| (a - b).abs() <= 1e-12),
            "{got:?} {want:?}"
        );
    };
    // Two fresh variables, `head` at its own rate.
    let fresh = || {
        let (head, other) = (var(), var());
        let vars = vec![
            ("head".to_string(), head.clone()),
            ("other".to_string(), other.clone()),
        ];
        let mut adam = Adam::new(vars, lr).unwrap();
        adam.scale_lr("head", scale).unwrap();
        (head, other, adam)
    };
    let (head, other, mut adam) = fresh();
    adam.step_with_slices(&[g.as_slice(), g.as_slice()], 0.0)
        .unwrap();
    close(&head, &want(lr * scale));
    close(&other, &want(lr));

    // Through a gradient store: the gradient of Σ g·θ is g.
    let (head, other, mut adam) = fresh();
    let gt = Tensor::from_vec(g.clone(), 4, &dev).unwrap();
    let loss = ((head.as_tensor() * &gt).unwrap().sum_all().unwrap()
        + (other.as_tensor() * &gt).unwrap().sum_all().unwrap())
    .unwrap();
    adam.step(&loss.backward().unwrap()).unwrap();
    close(&head, &want(lr * scale));
    close(&other, &want(lr));

    assert!(
        adam.scale_lr("nope", 0.5)
            .unwrap_err()
            .to_string()
            .contains("nope")
    );
    for bad in [0.0, -1.0, f64::NAN] {
        assert!(adam.scale_lr("head", bad).is_err());
    }
}

/// A clipped step equals the plain step on the scaled gradient (a power of two, so exactly),
/// the L2 term's gradient unscaled; the clipping state goes into the checkpoint's tensors and
/// back, and a bad factor is refused by name.
#[test]
fn a_clipped_step_scales_the_gradient_and_its_state_round_trips() {
    let make = |name: &str| {
        let v = Var::from_vec(
            (0..64)
                .map(|i| (i as f32 * 0.37).sin())
                .collect::<Vec<f32>>(),
            64,
            &Device::Cpu,
        )
        .unwrap();
        (
            Adam::new(vec![(name.to_string(), v.clone())], 1e-2).unwrap(),
            v,
        )
    };
    let g: Vec<f32> = (0..64).map(|i| (i as f32 * 0.11).cos()).collect();
    let half: Vec<f32> = g.iter().map(|x| x * 0.5).collect();
    let (mut a, va) = make("w");
    let (mut b, vb) = make("w");
    a.step_with_sources(&[GradSource::Slice(&g)], 0.3, 0.5)
        .unwrap();
    b.step_with_slices(&[half.as_slice()], 0.3).unwrap();
    let values = |v: &Var| -> Vec<f32> { v.as_tensor().to_vec1().unwrap() };
    assert_eq!(values(&va), values(&vb));

    let (mut c, _) = make("w");
    c.set_grad_clip(2.0).unwrap();
    for k in 0..25 {
        c.clip_scale(1.0 + k as f64);
    }
    let state: HashMap<String, Tensor> = c.state_tensors().unwrap().into_iter().collect();
    assert!(state.contains_key("adam.clip"));
    let (mut d, _) = make("w");
    d.set_grad_clip(2.0).unwrap();
    d.load_state(&state).unwrap();
    assert_eq!(d.grad_clip(), c.grad_clip());
    // A state without it (clipping was off) starts the mean afresh.
    let (plain, _) = make("w");
    let state: HashMap<String, Tensor> = plain.state_tensors().unwrap().into_iter().collect();
    d.load_state(&state).unwrap();
    assert_eq!(*d.grad_clip(), GradClip::new(2.0));
    for bad in [0.5, -1.0, f64::NAN] {
        let e = d.set_grad_clip(bad).unwrap_err().to_string();
        assert!(e.contains("grad_clip"), "{e}");
    }
}
