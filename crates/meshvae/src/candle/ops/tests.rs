use super::*;
use crate::numerics::rng::Rng;
use candle_core::{DType, Device, Var};

fn random(shape: &[usize], seed: u64) -> Var {
    let mut rng = Rng::new(seed);
    let n = shape.iter().product();
    Var::from_tensor(&Tensor::from_vec(rng.normals(n), shape, &Device::Cpu).unwrap()).unwrap()
}

fn max_diff(a: &Tensor, b: &Tensor) -> f64 {
    let d = (a.to_dtype(DType::F64).unwrap() - b.to_dtype(DType::F64).unwrap()).unwrap();
    d.abs().unwrap().max_all().unwrap().to_scalar().unwrap()
}

#[test]
fn tanh_and_l2_match_candle_ops_with_gradients() {
    // 40,000 elements: several chunks, and a partial last one.
    for dtype in [DType::F64, DType::F32] {
        let x = Var::from_tensor(&random(&[400, 100], 1).to_dtype(dtype).unwrap()).unwrap();
        let r = random(&[400, 100], 2).to_dtype(dtype).unwrap();
        let tol = if dtype == DType::F64 { 1e-12 } else { 1e-5 };
        let fused = tanh(x.as_tensor()).unwrap();
        let plain = x.tanh().unwrap();
        assert!(max_diff(&fused, &plain) < tol);
        let g1 = (&fused * &r)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        let g2 = (&plain * &r)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        assert!(max_diff(g1.get(&x).unwrap(), g2.get(&x).unwrap()) < tol);

        let l2 = half_sum_sq(x.as_tensor()).unwrap();
        let want = (x.sqr().unwrap().sum_all().unwrap() * 0.5).unwrap();
        assert!(max_diff(&l2, &want) < tol * 1e4);
        assert_eq!(l2.dims(), &[] as &[usize]);
        let g = (l2 * 3.0).unwrap().backward().unwrap();
        let want = (x.as_tensor() * 3.0).unwrap();
        assert!(max_diff(g.get(&x).unwrap(), &want) < tol);
    }
}

#[test]
fn fast_tanh_is_accurate_everywhere() {
    let mut worst = 0.0f64;
    let mut x = -12.0f32;
    while x <= 12.0 {
        let want = (x as f64).tanh();
        let got = fast_tanh(x) as f64;
        let err = (got - want).abs() / want.abs().max(1e-30);
        worst = worst.max(err);
        x += 1.3e-4;
    }
    assert!(worst < 5e-7, "{worst}");
    for x in [
        0.0f32,
        -0.0,
        1e-30,
        0.125,
        -0.125,
        9.0,
        -9.0,
        100.0,
        f32::MAX,
    ] {
        let want = (x as f64).tanh();
        assert!(
            (fast_tanh(x) as f64 - want).abs() <= 6e-8 * want.abs().max(1e-30),
            "{x}"
        );
    }
    assert!(fast_tanh(f32::NAN).is_nan());
}

#[test]
fn moments_are_two_pass_accurate() {
    // A large common offset: E[x²] − m² would lose most digits here.
    let x = (random(&[50_000, 3], 3).as_tensor() + 1e4).unwrap();
    let (mean, var) = channel_moments(&x).unwrap();
    let m = x.mean(0).unwrap();
    let v = x.broadcast_sub(&m).unwrap().sqr().unwrap().mean(0).unwrap();
    let (m, v): (Vec<f64>, Vec<f64>) = (m.to_vec1().unwrap(), v.to_vec1().unwrap());
    for j in 0..3 {
        assert!((mean[j] - m[j]).abs() < 1e-9);
        assert!(
            (var[j] - v[j]).abs() < 1e-9 * v[j],
            "{} vs {}",
            var[j],
            v[j]
        );
    }
}
