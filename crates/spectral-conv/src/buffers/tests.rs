//! Tests of the buffer-level kernels: against the candle ops, dense references, their adjoints,
//! and renumbered operators.

use super::*;
use crate::MaxPool;
use crate::test_util::{random_matrix, random_vec};
use candle_core::{Device, Tensor};

/// `[V, C, B]` → `[V, B, C]` (the candle ops' vertex-major layout).
fn vcb_to_vbc(x: &[f64], (v, c, b): (usize, usize, usize)) -> Vec<f64> {
    let mut out = vec![0.0; x.len()];
    for i in 0..v {
        for ch in 0..c {
            for bb in 0..b {
                out[(i * b + bb) * c + ch] = x[(i * c + ch) * b + bb];
            }
        }
    }
    out
}

fn vbc_to_vcb(x: &[f64], (v, c, b): (usize, usize, usize)) -> Vec<f64> {
    let mut out = vec![0.0; x.len()];
    for i in 0..v {
        for ch in 0..c {
            for bb in 0..b {
                out[(i * c + ch) * b + bb] = x[(i * b + bb) * c + ch];
            }
        }
    }
    out
}

#[test]
fn cheb_kernel_matches_the_candle_op_with_gradients() {
    let v = 90;
    let m = random_matrix(v, v, 0.05, 3);
    let op = SparseOp::new(&m, &Device::Cpu).unwrap();
    for (k, ci, co, batch) in [(1, 3, 2, 2), (2, 9, 4, 3), (3, 9, 9, 4), (4, 2, 3, 5)] {
        let kernel = ChebKernel::new(&op, k).unwrap();
        let d = ConvDims {
            batch,
            c_in: ci,
            c_out: co,
        };
        let x = random_vec(v * ci * batch, 1);
        let w = random_vec(ci * k * co, 2);
        let g = random_vec(v * co * batch, 4);
        let mut terms = vec![0.0; kernel.terms_len(batch, ci)];
        let mut y = vec![7.0; v * co * batch];
        kernel
            .forward(&x, &w, d, &mut terms, &mut y, &Workspace::new())
            .unwrap();
        // The candle op on the same data, [V, B, C].
        let xt = candle_core::Var::from_vec(
            vcb_to_vbc(&x, (v, ci, batch)),
            (v, batch, ci),
            &Device::Cpu,
        )
        .unwrap();
        let wt = candle_core::Var::from_vec(w.clone(), (ci * k, co), &Device::Cpu).unwrap();
        let conv =
            crate::ChebConv::from_weights(op.clone(), k, wt.as_tensor().clone(), None).unwrap();
        let yt = conv.forward_vertex_major(xt.as_tensor()).unwrap();
        let want = vbc_to_vcb(
            &yt.flatten_all().unwrap().to_vec1().unwrap(),
            (v, co, batch),
        );
        for (p, q) in y.iter().zip(&want) {
            assert!((p - q).abs() < 1e-12, "K={k}: forward {p} vs {q}");
        }
        let gt =
            Tensor::from_vec(vcb_to_vbc(&g, (v, co, batch)), (v, batch, co), &Device::Cpu).unwrap();
        let grads = (yt * gt).unwrap().sum_all().unwrap().backward().unwrap();
        let mut dw = vec![0.0; w.len()];
        let (mut dx, mut work) = (vec![5.0; x.len()], vec![3.0; kernel.work_len(batch, ci)]);
        kernel
            .backward(
                &x,
                &terms,
                &w,
                &g,
                d,
                &mut dw,
                Some((&mut dx, &mut work)),
                &Workspace::new(),
            )
            .unwrap();
        let want_dw: Vec<f64> = grads
            .get(&wt)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let want_dx = vbc_to_vcb(
            &grads
                .get(&xt)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap(),
            (v, ci, batch),
        );
        for (p, q) in dw.iter().zip(&want_dw).chain(dx.iter().zip(&want_dx)) {
            assert!(
                (p - q).abs() < 1e-10 * q.abs().max(1.0),
                "K={k}: {p} vs {q}"
            );
        }
        // Without dx, dW is the same.
        let mut dw2 = vec![0.0; w.len()];
        kernel
            .backward(&x, &terms, &w, &g, d, &mut dw2, None, &Workspace::new())
            .unwrap();
        assert_eq!(dw, dw2);
    }
    let kernel = ChebKernel::new(&op, 3).unwrap();
    let d = ConvDims {
        batch: 2,
        c_in: 3,
        c_out: 3,
    };
    let err = kernel
        .forward(
            &[0.0; 5],
            &[0.0; 27],
            d,
            &mut [],
            &mut [0.0; 540],
            &Workspace::new(),
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("x has 5 values"), "{err}");
    assert!(ChebKernel::new(&op, 0).is_err() && ChebKernel::new(&op, 9).is_err());
}

/// Rows of `[V, n]` data moved to a new order: row p of the result is row `order[p]`.
fn reorder(x: &[f64], order: &[u32], n: usize) -> Vec<f64> {
    order
        .iter()
        .flat_map(|&o| x[o as usize * n..][..n].iter().copied())
        .collect()
}

#[test]
fn renumbered_kernels_give_the_renumbered_results() {
    let v = 60;
    let m = random_matrix(v, v, 0.08, 21);
    let op = SparseOp::new(&m, &Device::Cpu).unwrap();
    let kernel = ChebKernel::new(&op, 3).unwrap();
    let order = kernel.locality_order();
    assert_ne!(
        order,
        (0..v as u32).collect::<Vec<_>>(),
        "a real renumbering"
    );
    let moved = kernel.permuted(&order).unwrap();
    assert!(
        moved.far_share(10) < kernel.far_share(10),
        "closer neighbours"
    );
    assert_eq!(kernel.far_share(v), 0.0);
    let (ci, co, batch) = (4, 3, 5);
    let d = ConvDims {
        batch,
        c_in: ci,
        c_out: co,
    };
    let (x, w, g) = (
        random_vec(v * ci * batch, 1),
        random_vec(ci * 3 * co, 2),
        random_vec(v * co * batch, 3),
    );
    let ws = Workspace::new();
    let run = |k: &ChebKernel, x: &[f64], g: &[f64]| {
        let mut terms = vec![0.0; k.terms_len(batch, ci)];
        let mut y = vec![0.0; v * co * batch];
        k.forward(x, &w, d, &mut terms, &mut y, &ws).unwrap();
        let (mut dw, mut dx, mut work) =
            (vec![0.0; w.len()], vec![0.0; x.len()], vec![0.0; x.len()]);
        k.backward(
            x,
            &terms,
            &w,
            g,
            d,
            &mut dw,
            Some((&mut dx, &mut work)),
            &ws,
        )
        .unwrap();
        (y, dw, dx)
    };
    let (y, dw, dx) = run(&kernel, &x, &g);
    let (x2, g2) = (
        reorder(&x, &order, ci * batch),
        reorder(&g, &order, co * batch),
    );
    let (y2, dw2, dx2) = run(&moved, &x2, &g2);
    let close = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .all(|(p, q)| (p - q).abs() < 1e-12 * q.abs().max(1.0))
    };
    assert!(close(&y2, &reorder(&y, &order, co * batch)), "forward");
    assert!(close(&dx2, &reorder(&dx, &order, ci * batch)), "dx");
    assert!(close(&dw2, &dw), "dW does not depend on the numbering");
    let e = kernel.permuted(&order[1..]).unwrap_err().to_string();
    assert!(
        e.contains("ChebKernel::permuted") && e.contains("order"),
        "{e}"
    );

    // A pooling operator (30 × 60) with renumbered columns, and its de-pooling adjoint
    // with renumbered rows.
    let p =
        SparseKernel::new(&SparseOp::new(&random_matrix(30, v, 0.1, 22), &Device::Cpu).unwrap());
    let rows: Vec<u32> = (0..30).rev().collect();
    let moved = p.permuted(Some(&rows), Some(&order)).unwrap();
    let n = 7;
    let x = random_vec(v * n, 5);
    let (mut y, mut y2) = (vec![0.0; 30 * n], vec![0.0; 30 * n]);
    p.apply(&x, &mut y, n).unwrap();
    moved.apply(&reorder(&x, &order, n), &mut y2, n).unwrap();
    assert!(close(&y2, &reorder(&y, &rows, n)), "pooling");
    let z = random_vec(30 * n, 6);
    let (mut t, mut t2) = (vec![0.0; v * n], vec![0.0; v * n]);
    p.apply_t(&z, &mut t, n).unwrap();
    moved.apply_t(&reorder(&z, &rows, n), &mut t2, n).unwrap();
    assert!(close(&t2, &reorder(&t, &order, n)), "the adjoint");
    // 30 entries for 60 columns.
    let e = p.permuted(None, Some(&rows)).unwrap_err().to_string();
    assert!(
        e.contains("SparseKernel::permuted") && e.contains("cols"),
        "{e}"
    );
}

#[test]
fn sparse_and_max_pool_kernels_match_dense_and_their_adjoints() {
    let m = random_matrix(30, 70, 0.1, 5);
    let op = SparseOp::new(&m, &Device::Cpu).unwrap();
    let kernel = SparseKernel::new(&op);
    let n = 6;
    let x = random_vec(70 * n, 6);
    let g = random_vec(30 * n, 7);
    let (mut y, mut back) = (vec![0.0; 30 * n], vec![0.0; 70 * n]);
    kernel.apply(&x, &mut y, n).unwrap();
    kernel.apply_t(&g, &mut back, n).unwrap();
    let want = crate::test_util::dense_apply(&m, &x, 1, n);
    assert!(y.iter().zip(&want).all(|(p, q)| (p - q).abs() < 1e-12));
    // <g, A x> = <Aᵀ g, x>.
    let lhs: f64 = g.iter().zip(&y).map(|(a, b)| a * b).sum();
    let rhs: f64 = back.iter().zip(&x).map(|(a, b)| a * b).sum();
    assert!((lhs - rhs).abs() < 1e-10 * lhs.abs().max(1.0));
    assert!(kernel.apply(&x[1..], &mut y, n).is_err());

    let pool = MaxPool::new(&m, &Device::Cpu).unwrap();
    let (mut py, mut arg) = (vec![0.0; 30 * n], vec![0u32; 30 * n]);
    pool.kernel()
        .forward_into(&x, &mut py, &mut arg, n)
        .unwrap();
    let xt = Tensor::from_vec(x.clone(), (70, 1, n), &Device::Cpu).unwrap();
    let want: Vec<f64> = pool
        .forward_vertex_major(&xt)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    assert_eq!(py, want);
    let mut dx = vec![9.0; 70 * n];
    pool.kernel().backward_into(&arg, &g, &mut dx, n).unwrap();
    let lhs: f64 = g.iter().zip(&py).map(|(a, b)| a * b).sum();
    let rhs: f64 = dx.iter().zip(&x).map(|(a, b)| a * b).sum();
    assert!((lhs - rhs).abs() < 1e-10 * lhs.abs().max(1.0));

    // The kernel built from the matrix alone (no device) selects and scatters the same.
    let kernel = MaxKernel::from_matrix(&m, MaxMode::SignedMax).unwrap();
    let (mut ky, mut karg) = (vec![0.0; 30 * n], vec![0u32; 30 * n]);
    kernel.forward_into(&x, &mut ky, &mut karg, n).unwrap();
    assert_eq!((ky, karg), (py, arg.clone()));
    let mut kdx = vec![0.0; 70 * n];
    kernel.backward_into(&arg, &g, &mut kdx, n).unwrap();
    assert_eq!(kdx, dx);
    let empty = CsrMatrix::from_triplets(3, 0, &[]).unwrap();
    let err = MaxKernel::from_matrix(&empty, MaxMode::PlainMax).unwrap_err();
    assert!(err.to_string().contains("0 fine vertices"), "{err}");
}

#[test]
fn graph_max_pool_buffers_match_the_candle_op_and_its_gradient() {
    // Overlapping member lists: each coarse vertex takes a random ~10% of 70 fine ones.
    let m = random_matrix(30, 70, 0.1, 11);
    let pool = MaxPool::with_mode(&m, crate::MaxMode::PlainMax, &Device::Cpu).unwrap();
    let n = 6;
    let x = random_vec(70 * n, 12);
    let g = random_vec(30 * n, 13);
    let (mut y, mut arg) = (vec![0.0; 30 * n], vec![0u32; 30 * n]);
    pool.kernel().forward_into(&x, &mut y, &mut arg, n).unwrap();
    let xt = candle_core::Var::from_vec(x.clone(), (70, 1, n), &Device::Cpu).unwrap();
    let yt = pool.forward_vertex_major(xt.as_tensor()).unwrap();
    let want: Vec<f64> = yt.flatten_all().unwrap().to_vec1().unwrap();
    assert_eq!(y, want);
    let gt = Tensor::from_vec(g.clone(), (30, 1, n), &Device::Cpu).unwrap();
    let grads = (yt * gt).unwrap().sum_all().unwrap().backward().unwrap();
    let want_dx: Vec<f64> = grads
        .get(xt.as_tensor())
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    let mut dx = vec![9.0; 70 * n];
    pool.kernel().backward_into(&arg, &g, &mut dx, n).unwrap();
    for (p, q) in dx.iter().zip(&want_dx) {
        assert!((p - q).abs() < 1e-14, "{p} vs {q}");
    }
    // Some fine vertex was selected by more than one row and got the sum.
    let mut times = vec![0usize; 70 * n];
    for (i, &j) in arg.iter().enumerate() {
        if j != u32::MAX {
            times[j as usize * n + i % n] += 1;
        }
    }
    assert!(times.iter().any(|&t| t > 1));
    assert!(
        pool.kernel()
            .backward_into(&arg, &g[1..], &mut dx, n)
            .is_err()
    );
}

#[test]
fn max_pool_blocks_match_a_plain_loop_and_unpool_is_the_same_on_any_thread_count() {
    // 40 values per vertex: two blocks of 16 and a tail of 8 in the forward kernel.
    let m = random_matrix(50, 120, 0.08, 14);
    let n = 40;
    let x = random_vec(120 * n, 15);
    let g = random_vec(50 * n, 16);
    for mode in [crate::MaxMode::PlainMax, crate::MaxMode::SignedMax] {
        let pool = MaxPool::with_mode(&m, mode, &Device::Cpu).unwrap();
        let (mut y, mut arg) = (vec![0.0; 50 * n], vec![0u32; 50 * n]);
        pool.kernel().forward_into(&x, &mut y, &mut arg, n).unwrap();
        for r in 0..50 {
            for k in 0..n {
                let (mut best, mut at) = (0.0f64, u32::MAX);
                for &j in m.row(r).0 {
                    let v = x[j as usize * n + k];
                    let better = match mode {
                        crate::MaxMode::PlainMax => v > best,
                        crate::MaxMode::SignedMax => {
                            v.abs() > best.abs() || (v.abs() == best.abs() && v < best)
                        }
                    };
                    if at == u32::MAX || better {
                        (best, at) = (v, j);
                    }
                }
                assert_eq!((y[r * n + k], arg[r * n + k]), (best, at), "{mode:?}");
            }
        }
        let run = |threads: usize| {
            let mut dx = vec![0.0; 120 * n];
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| pool.kernel().backward_into(&arg, &g, &mut dx, n).unwrap());
            dx
        };
        let one = run(1);
        assert_eq!(one, run(2));
        assert_eq!(one, run(5));
        // And it is the plain scatter-add.
        let mut want = vec![0.0; 120 * n];
        for (i, &j) in arg.iter().enumerate() {
            if j != u32::MAX {
                want[j as usize * n + i % n] += g[i];
            }
        }
        assert_eq!(one, want);
    }
}

/// Timing probe (not a test of results): `cargo test --release -p spectral-conv --lib --
/// --ignored --nocapture graph_pool_timing_probe`. Graph max pooling on a 205×205 grid
/// (clusters of two vertices, so about half survive) at n = 288 values per vertex (B = 32,
/// C = 9), against mean pooling over the same clusters.
#[test]
#[ignore]
fn graph_pool_timing_probe() {
    let (rows, cols) = (205usize, 205usize);
    let v = rows * cols;
    let faces = crate::test_util::grid_faces(rows, cols);
    let half = cols.div_ceil(2);
    let cluster_of: Vec<u32> = (0..v)
        .map(|u| ((u / cols) * half + (u % cols) / 2) as u32)
        .collect();
    let survivors: Vec<u32> = (0..rows * half)
        .map(|c| ((c / half) * cols + (c % half) * 2) as u32)
        .collect();
    let members = crate::test_util::neighbourhoods(&faces, &survivors, &cluster_of);
    let m = members.rows();
    let n = 288;
    let x: Vec<f32> = random_vec(v * n, 1).iter().map(|&a| a as f32).collect();
    let pool = MaxPool::with_mode(&members, crate::MaxMode::PlainMax, &Device::Cpu).unwrap();
    let signed = MaxPool::new(&members, &Device::Cpu).unwrap();
    let (mut y, mut arg, mut dx) = (vec![0f32; m * n], vec![0u32; m * n], vec![0f32; v * n]);
    // The fastest of 10 calls: the machine is shared.
    let time = |label: &str, f: &mut dyn FnMut()| {
        let mut best = f64::INFINITY;
        for _ in 0..10 {
            let t = std::time::Instant::now();
            f();
            best = best.min(t.elapsed().as_secs_f64() * 1e3);
        }
        println!("{label}: {best:.1} ms");
    };
    println!("{v} -> {m} vertices, {} memberships", members.nnz());
    time("graph pool forward_into", &mut || {
        pool.kernel().forward_into(&x, &mut y, &mut arg, n).unwrap()
    });
    time("signed max pool forward_into", &mut || {
        signed
            .kernel()
            .forward_into(&x, &mut y, &mut arg, n)
            .unwrap()
    });
    time("graph pool backward_into", &mut || {
        pool.kernel().backward_into(&arg, &y, &mut dx, n).unwrap()
    });
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    time("graph pool backward_into, 1 thread", &mut || {
        one.install(|| pool.kernel().backward_into(&arg, &y, &mut dx, n).unwrap())
    });
    let mean = SparseKernel::new(&SparseOp::new(&members, &Device::Cpu).unwrap());
    time("sparse product, same pattern", &mut || {
        mean.apply(&x, &mut y, n).unwrap()
    });
}

/// Kernels made from the matrix alone (no candle operator, no device) compute what the
/// kernels of a `SparseOp` compute, to the bit; bad arguments are refused by name.
#[test]
fn kernels_from_the_matrix_equal_those_of_the_candle_operator() {
    let v = 40;
    let m = random_matrix(v, v, 0.1, 31);
    let op = SparseOp::new(&m, &Device::Cpu).unwrap();
    let d = ConvDims {
        batch: 3,
        c_in: 4,
        c_out: 5,
    };
    let x = random_vec(v * d.c_in * d.batch, 32);
    let w = random_vec(d.c_in * 3 * d.c_out, 33);
    let run = |kernel: &ChebKernel| {
        let mut terms = vec![0.0; kernel.terms_len(d.batch, d.c_in)];
        let mut y = vec![0.0; v * d.c_out * d.batch];
        kernel
            .forward(&x, &w, d, &mut terms, &mut y, &Workspace::new())
            .unwrap();
        y
    };
    let from_op = run(&ChebKernel::new(&op, 3).unwrap());
    let from_matrix = run(&ChebKernel::from_matrix(&m, 3).unwrap());
    assert_eq!(from_op, from_matrix);

    let rect = random_matrix(12, v, 0.2, 34);
    let (a, b) = (
        SparseKernel::new(&SparseOp::new(&rect, &Device::Cpu).unwrap()),
        SparseKernel::from_matrix(&rect).unwrap(),
    );
    let xs = random_vec(v * 2, 35);
    let (mut ya, mut yb) = (vec![0.0; 12 * 2], vec![1.0; 12 * 2]);
    a.apply(&xs, &mut ya, 2).unwrap();
    b.apply(&xs, &mut yb, 2).unwrap();
    assert_eq!(ya, yb);
    let xt = random_vec(12 * 2, 36);
    let (mut ta, mut tb) = (vec![0.0; v * 2], vec![1.0; v * 2]);
    a.apply_t(&xt, &mut ta, 2).unwrap();
    b.apply_t(&xt, &mut tb, 2).unwrap();
    assert_eq!(ta, tb);

    let err = ChebKernel::from_matrix(&rect, 3).unwrap_err().to_string();
    assert!(
        err.contains("ChebKernel::from_matrix") && err.contains("not square"),
        "{err}"
    );
    let err = ChebKernel::from_matrix(&m, 9).unwrap_err().to_string();
    assert!(err.contains("k") && err.contains("1 ..= 8"), "{err}");
}
