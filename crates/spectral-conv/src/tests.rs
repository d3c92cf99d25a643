//! The vertex-major layout `[V, B, C]`: every layer against its `[B, V, C]` form on permuted
//! tensors (values and gradients), the fused Chebyshev op against f64 central finite
//! differences, and the bit-reproducibility of its weight gradient.

use crate::test_util::*;
use crate::{Backend, ChebConv, DePool, MaxPool, MeanPool, Sampling, SparseOp, SpatialConv};
use candle_core::{DType, Device, Tensor, Var};
use sparse_csr::CsrMatrix;

/// `[B, V, C]` ↔ `[V, B, C]` (contiguous).
fn swap(t: &Tensor) -> Tensor {
    t.transpose(0, 1).unwrap().contiguous().unwrap()
}

fn cast(t: &Tensor, dtype: DType) -> Tensor {
    t.to_dtype(dtype).unwrap()
}

/// The gradients of sum(r ⊙ y) for the given vars, in order.
fn grads_of(y: &Tensor, r: &Tensor, vars: &[&Var]) -> Vec<Tensor> {
    let g = (y * r).unwrap().sum_all().unwrap().backward().unwrap();
    vars.iter()
        .map(|v| g.get(v).expect("a gradient").clone())
        .collect()
}

#[test]
fn cheb_vertex_major_matches_batch_major_and_the_fallback() {
    // Non-symmetric operator; V = 131 spans three kernel chunks; odd batches hit the lane tails.
    let v = 131;
    let op = SparseOp::new(&random_matrix(v, v, 0.03, 5), &Device::Cpu).unwrap();
    for (k, ci, co, batch, bias) in [
        (1, 3, 2, 5, true),
        (2, 4, 3, 11, false),
        (3, 9, 9, 33, true),
        (3, 5, 7, 3, false),
        (5, 2, 4, 9, true),
    ] {
        let w0 = tensor(random_vec(ci * k * co, 1), &[ci * k, co]);
        let b0 = tensor(random_vec(co, 2), &[co]);
        let x0 = tensor(random_vec(batch * v * ci, 3), &[batch, v, ci]);
        let r0 = tensor(random_vec(batch * v * co, 4), &[batch, v, co]);
        for (dtype, tol) in [(DType::F64, 1e-12), (DType::F32, 1e-6)] {
            let case = format!("K={k} ci={ci} co={co} B={batch} {dtype:?}");
            let w = Var::from_tensor(&cast(&w0, dtype)).unwrap();
            let b = Var::from_tensor(&cast(&b0, dtype)).unwrap();
            let x = Var::from_tensor(&cast(&x0, dtype)).unwrap();
            let xv = Var::from_tensor(&swap(x.as_tensor())).unwrap();
            let r = cast(&r0, dtype);
            let layer = |backend| {
                let bias = bias.then(|| b.as_tensor().clone());
                ChebConv::from_weights(op.with_backend(backend), k, w.as_tensor().clone(), bias)
                    .unwrap()
            };
            let conv = layer(Backend::Kernel);
            let y_bm = conv.forward(x.as_tensor()).unwrap();
            let y_vm = conv.forward_vertex_major(xv.as_tensor()).unwrap();
            assert_eq!(y_vm.dims(), &[v, batch, co]);
            assert!(max_abs_diff(&swap(&y_bm), &y_vm) < tol, "{case}: forward");
            let vars: Vec<&Var> = if bias { vec![&w, &b] } else { vec![&w] };
            let mut bm_vars = vec![&x];
            bm_vars.extend(&vars);
            let mut vm_vars = vec![&xv];
            vm_vars.extend(&vars);
            let g_bm = grads_of(&y_bm, &r, &bm_vars);
            let g_vm = grads_of(&y_vm, &swap(&r), &vm_vars);
            assert!(max_abs_diff(&swap(&g_bm[0]), &g_vm[0]) < tol, "{case}: dx");
            for (p, q) in g_bm[1..].iter().zip(&g_vm[1..]) {
                let scale = 1.0 + to_vec(p).iter().fold(0.0f64, |m, v| m.max(v.abs()));
                assert!(max_abs_diff(p, q) < tol * scale, "{case}: dW/db");
            }
            if dtype == DType::F64 {
                // An independent reference: the candle-ops fallback, in the same layout.
                let fallback = layer(Backend::Fallback);
                let y_fb = fallback.forward_vertex_major(xv.as_tensor()).unwrap();
                assert!(
                    max_abs_diff(&y_fb, &y_vm) < 1e-12,
                    "{case}: fallback forward"
                );
                let g_fb = grads_of(&y_fb, &swap(&r), &vm_vars);
                for (p, q) in g_fb.iter().zip(&g_vm) {
                    assert!(max_abs_diff(p, q) < 1e-10, "{case}: fallback gradients");
                }
            }
        }
    }
}

#[test]
fn cheb_vertex_major_gradients_match_finite_differences() {
    let faces = grid_faces(4, 5);
    let l = mesh_laplacian(20, &faces);
    let op = SparseOp::new(&l, &Device::Cpu).unwrap();
    for (k, ci, co, batch) in [(1, 3, 2, 3), (2, 2, 3, 1), (3, 3, 2, 3), (5, 2, 2, 2)] {
        let x =
            Var::from_tensor(&tensor(random_vec(20 * batch * ci, 41), &[20, batch, ci])).unwrap();
        let w = Var::from_tensor(&tensor(random_vec(ci * k * co, 42), &[ci * k, co])).unwrap();
        let b = Var::from_tensor(&tensor(random_vec(co, 43), &[co])).unwrap();
        let conv = ChebConv::from_weights(
            op.clone(),
            k,
            w.as_tensor().clone(),
            Some(b.as_tensor().clone()),
        )
        .unwrap();
        let loss = || {
            let y = conv
                .forward_vertex_major(x.as_tensor())
                .map_err(candle_core::Error::wrap)?;
            weighted_sum(&y.tanh()?, 44)
        };
        let err = grad_check(&[&x, &w, &b], loss);
        assert!(err < 1e-7, "K={k}: relative error {err}");
    }
}

#[test]
fn cheb_vertex_major_takes_strided_inputs_and_broadcast_gradients() {
    let v = 70;
    let op = SparseOp::new(&random_matrix(v, v, 0.05, 8), &Device::Cpu).unwrap();
    let w = Var::from_tensor(&tensor(random_vec(27 * 9, 9), &[27, 9])).unwrap();
    let conv = ChebConv::from_weights(op, 3, w.as_tensor().clone(), None).unwrap();
    let bvc = tensor(random_vec(4 * v * 9, 10), &[4, v, 9]);
    // A transposed view (not contiguous) and its contiguous copy.
    let view = bvc.transpose(0, 1).unwrap();
    assert!(!view.is_contiguous());
    let y_view = conv.forward_vertex_major(&view).unwrap();
    let y_copy = conv.forward_vertex_major(&swap(&bvc)).unwrap();
    assert_eq!(to_vec(&y_view), to_vec(&y_copy));
    // sum_all's backward hands the op a zero-stride gradient of ones.
    let x = Var::from_tensor(&swap(&bvc)).unwrap();
    let y = conv.forward_vertex_major(x.as_tensor()).unwrap();
    let g = y.sum_all().unwrap().backward().unwrap();
    let ones = Tensor::ones(y.dims(), DType::F64, &Device::Cpu).unwrap();
    let want = grads_of(
        &conv.forward_vertex_major(x.as_tensor()).unwrap(),
        &ones,
        &[&x, &w],
    );
    assert!(max_abs_diff(g.get(&x).unwrap(), &want[0]) < 1e-12);
    assert!(max_abs_diff(g.get(&w).unwrap(), &want[1]) < 1e-12);
    // A [B, V, C] tensor in the vertex-major call is a shape error, not a panic.
    assert!(conv.forward_vertex_major(&bvc).is_err());
}

#[test]
fn weight_gradients_are_bit_reproducible_across_thread_counts() {
    let v = 300;
    let op = SparseOp::new(&random_matrix(v, v, 0.02, 12), &Device::Cpu).unwrap();
    let w = Var::from_tensor(
        &tensor(random_vec(27 * 9, 13), &[27, 9])
            .to_dtype(DType::F32)
            .unwrap(),
    )
    .unwrap();
    let b = Var::from_tensor(&Tensor::zeros(9, DType::F32, &Device::Cpu).unwrap()).unwrap();
    let x = tensor(random_vec(v * 32 * 9, 14), &[v, 32, 9])
        .to_dtype(DType::F32)
        .unwrap();
    let r = tensor(random_vec(v * 32 * 9, 15), &[v, 32, 9])
        .to_dtype(DType::F32)
        .unwrap();
    let conv =
        ChebConv::from_weights(op, 3, w.as_tensor().clone(), Some(b.as_tensor().clone())).unwrap();
    // The SIMD variant must not change between the runs (another test may force the baseline).
    let _lock = crate::kernel::BASELINE_LOCK.lock();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let y = conv.forward_vertex_major(&x).unwrap();
            let g = grads_of(&y, &r, &[&w, &b]);
            (
                g[0].flatten_all().unwrap().to_vec1::<f32>().unwrap(),
                g[1].to_vec1::<f32>().unwrap(),
            )
        })
    };
    let one = run(1);
    assert_eq!(one, run(3));
    assert_eq!(one, run(1));
}

/// `[B, V, C]` and `[V, B, C]` applications of one layer agree, values and input gradients.
fn check_layer(
    name: &str,
    bm: impl Fn(&Tensor) -> crate::Result<Tensor>,
    vm: impl Fn(&Tensor) -> crate::Result<Tensor>,
    shape: (usize, usize, usize),
) {
    for (dtype, tol) in [(DType::F64, 1e-12), (DType::F32, 1e-6)] {
        let x = Var::from_tensor(&cast(
            &tensor(
                random_vec(shape.0 * shape.1 * shape.2, 20),
                &[shape.0, shape.1, shape.2],
            ),
            dtype,
        ))
        .unwrap();
        let xv = Var::from_tensor(&swap(x.as_tensor())).unwrap();
        let y_bm = bm(x.as_tensor()).unwrap();
        let y_vm = vm(xv.as_tensor()).unwrap();
        assert!(
            max_abs_diff(&swap(&y_bm), &y_vm) < tol,
            "{name} {dtype:?}: forward"
        );
        let r = cast(
            &tensor(random_vec(y_bm.elem_count(), 21), y_bm.dims()),
            dtype,
        );
        let g_bm = grads_of(&y_bm, &r, &[&x]);
        let g_vm = grads_of(&y_vm, &swap(&r), &[&xv]);
        assert!(
            max_abs_diff(&swap(&g_bm[0]), &g_vm[0]) < tol,
            "{name} {dtype:?}: gradient"
        );
        // Rank 2 ([V, C]) is one batch.
        let x2 = x.as_tensor().get(0).unwrap();
        let y2 = vm(&x2).unwrap();
        assert!(
            max_abs_diff(&y2, &y_bm.get(0).unwrap()) < tol,
            "{name}: rank 2"
        );
    }
}

#[test]
fn sparse_layers_and_pools_vertex_major_match_batch_major() {
    // 10 fine vertices in clusters {0, 4, 7}, {1, 2}, {3, 5, 6, 9}, {8}, and an empty one.
    let clusters: [&[u32]; 5] = [&[0, 4, 7], &[1, 2], &[3, 5, 6, 9], &[8], &[]];
    let mut t = Vec::new();
    for (c, members) in clusters.iter().enumerate() {
        t.extend(
            members
                .iter()
                .map(|&m| (c as u32, m, 1.0 / members.len() as f64)),
        );
    }
    let p = CsrMatrix::from_triplets(5, 10, &t).unwrap();
    let dev = Device::Cpu;
    for backend in [Backend::Kernel, Backend::Fallback] {
        let pool = MeanPool::new(&p, &dev).unwrap().with_backend(backend);
        check_layer(
            "mean pool",
            |x| pool.forward(x),
            |x| pool.forward_vertex_major(x),
            (3, 10, 4),
        );
        let depool = DePool::new(&p.transpose(), &dev)
            .unwrap()
            .with_backend(backend);
        let (f, g) = (
            |x: &Tensor| depool.forward(x),
            |x: &Tensor| depool.forward_vertex_major(x),
        );
        check_layer("de-pool", f, g, (3, 5, 4));
        let up = Sampling::new(&random_matrix(10, 5, 0.4, 22), &dev)
            .unwrap()
            .with_backend(backend);
        check_layer(
            "sampling",
            |x| up.forward(x),
            |x| up.forward_vertex_major(x),
            (5, 5, 2),
        );
        let op = SparseOp::new(&random_matrix(9, 10, 0.3, 23), &dev)
            .unwrap()
            .with_backend(backend);
        let (f, g) = (
            |x: &Tensor| op.apply(x),
            |x: &Tensor| op.apply_vertex_major(x),
        );
        check_layer("sparse op", f, g, (3, 10, 3));
        let max = MaxPool::new(&p, &dev).unwrap().with_backend(backend);
        let (f, g) = (
            |x: &Tensor| max.forward(x),
            |x: &Tensor| max.forward_vertex_major(x),
        );
        check_layer("max pool", f, g, (3, 10, 4));
        let graph = MaxPool::with_mode(&p, crate::MaxMode::PlainMax, &dev)
            .unwrap()
            .with_backend(backend);
        let (f, g) = (
            |x: &Tensor| graph.forward(x),
            |x: &Tensor| graph.forward_vertex_major(x),
        );
        check_layer("graph max pool", f, g, (3, 10, 4));
        let mean = crate::neighbour_mean_matrix(&adjacency(16, &grid_faces(4, 4))).unwrap();
        let nb = SparseOp::new(&mean, &dev).unwrap().with_backend(backend);
        let w = |seed| tensor(random_vec(3 * 2, seed), &[3, 2]);
        let bias = Some(tensor(random_vec(2, 26), &[2]));
        let spatial = SpatialConv::from_weights(nb, w(24), w(25), bias).unwrap();
        let cast_layer = |x: &Tensor, vm: bool| {
            let dtype = x.dtype();
            let s = SpatialConv::from_weights(
                spatial.neighbour_mean().clone(),
                cast(spatial.w_self(), dtype),
                cast(spatial.w_nb(), dtype),
                spatial.bias().map(|b| cast(b, dtype)),
            )?;
            if vm {
                s.forward_vertex_major(x)
            } else {
                s.forward(x)
            }
        };
        check_layer(
            "spatial",
            |x| cast_layer(x, false),
            |x| cast_layer(x, true),
            (2, 16, 3),
        );
    }
    // Wrong vertex counts and ranks are typed errors.
    let pool = MeanPool::new(&p, &dev).unwrap();
    let wrong = Tensor::zeros((9, 2, 3), DType::F32, &dev).unwrap();
    assert!(pool.forward_vertex_major(&wrong).is_err());
    let rank4 = Tensor::zeros((10, 1, 2, 3), DType::F32, &dev).unwrap();
    assert!(pool.forward_vertex_major(&rank4).is_err());
    assert!(
        MaxPool::new(&p, &dev)
            .unwrap()
            .forward_vertex_major(&wrong)
            .is_err()
    );
}

/// Timing probe (not a test of results): `cargo test --release -p spectral-conv -- --ignored
/// --nocapture timing_probe`.
#[test]
#[ignore]
fn timing_probe() {
    let n = 205;
    let v = n * n;
    let l = mesh_laplacian(v, &grid_faces(n, n));
    let op = SparseOp::new(&l, &Device::Cpu).unwrap();
    let w = Var::from_tensor(
        &(tensor(random_vec(27 * 9, 1), &[27, 9])
            .to_dtype(DType::F32)
            .unwrap()
            * 0.1)
            .unwrap(),
    )
    .unwrap();
    let conv = ChebConv::from_weights(op, 3, w.as_tensor().clone(), None).unwrap();
    let xb = Var::from_tensor(
        &tensor(random_vec(v * 32 * 9, 2), &[32, v, 9])
            .to_dtype(DType::F32)
            .unwrap(),
    )
    .unwrap();
    let xv = Var::from_tensor(&swap(xb.as_tensor())).unwrap();
    // [V, C, B], through the op directly (the layers do not offer it): for the layout choice.
    let xc = Var::from_tensor(
        &xb.as_tensor()
            .permute((1, 2, 0))
            .unwrap()
            .contiguous()
            .unwrap(),
    )
    .unwrap();
    let lap = conv.laplacian().clone();
    let vcb = |x: &Tensor| {
        let op = crate::cheb_op::ChebOp::new(
            lap.csr().clone(),
            lap.csr_t().clone(),
            3,
            crate::layout::Io::VertexChannel,
            lap.workspace().clone(),
        );
        x.apply_op2(w.as_tensor(), op)
    };
    // CPU time of the process (utime + stime, in clock ticks of 10 ms): less sensitive to the
    // other jobs on a shared machine than wall time.
    let cpu_ms = || {
        let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
        let fields: Vec<&str> = stat
            .rsplit(')')
            .next()
            .unwrap_or("")
            .split_whitespace()
            .collect();
        let tick = |i: usize| {
            fields
                .get(i)
                .and_then(|v| v.parse::<f64>().ok())
                .unwrap_or(0.0)
        };
        (tick(11) + tick(12)) * 10.0
    };
    for (name, x, vm) in [
        ("[B, V, C]", &xb, 0),
        ("[V, B, C]", &xv, 1),
        ("[V, C, B]", &xc, 2),
    ] {
        let fwd = || match vm {
            0 => conv.forward(x.as_tensor()).unwrap(),
            1 => conv.forward_vertex_major(x.as_tensor()).unwrap(),
            _ => vcb(x.as_tensor()).unwrap(),
        };
        let reps = 10;
        let (mut wall_f, mut wall_fb) = (Vec::new(), Vec::new());
        let c0 = cpu_ms();
        for _ in 0..reps {
            let t = std::time::Instant::now();
            std::hint::black_box(fwd());
            wall_f.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let c1 = cpu_ms();
        for _ in 0..reps {
            let t = std::time::Instant::now();
            let g = fwd().backward().unwrap();
            std::hint::black_box(g.get(x).unwrap().dims());
            wall_fb.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let c2 = cpu_ms();
        wall_f.sort_by(f64::total_cmp);
        wall_fb.sort_by(f64::total_cmp);
        println!(
            "{name}: fwd wall min {:.1} median {:.1} ms, CPU {:.1} ms/iter; fwd+bwd wall min {:.1} median {:.1} ms, CPU {:.1} ms/iter",
            wall_f[0],
            wall_f[reps / 2],
            (c1 - c0) / reps as f64,
            wall_fb[0],
            wall_fb[reps / 2],
            (c2 - c1) / reps as f64
        );
    }
}
