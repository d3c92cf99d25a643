//! spectral-conv: ChebConv (K = 3) forward and forward + backward at B = 32, C = 9 on the
//! horse-gallop (8,431 vertices) and elephant-gallop (42,321 vertices) graphs; the sparse product
//! as custom op against the candle-ops fallback; mean pooling and de-pooling; and a copy loop that
//! measures the memory bandwidth the figures are compared with.
//!
//! `cargo bench -p meshvae-benches --bench conv` (needs ../shared/datasets unpacked).
//! Forward + backward = forward, loss = sum(r ⊙ y) with a fixed random r, `backward()`, with both
//! the input and the weights requiring gradients (an inner layer of a network).
//! "vertex-major" rows take and return `[V, B, C]` (`forward_vertex_major`), the layout a network
//! keeps throughout so that no layer transposes.
//! "buffer-level" rows run the same kernels on caller-owned `[V, C, B]` slices
//! (`spectral_conv::ChebKernel`, `SparseKernel`), as meshvae's training engine does: no tensor
//! allocation, no autograd.
//! Pooling and de-pooling use mesh-hierarchy's operators for our pooler (modified QEM to half the
//! vertices, mean pooling, de-pooling by copy). SpiralNet++'s convolution (spirals of 9, 32 → 32
//! channels, B = 32, horse-gallop) runs as spectral-conv's `SpiralConv` op against the gathered
//! matrix of candle ops (its fallback). On elephant-gallop the ablation's other two
//! poolings sit beside them: graph max pooling (the same coarse vertices, the plain max over
//! each survivor's one-ring ∪ cluster; de-pooling by the mean over the neighbourhoods holding a
//! vertex) and remeshing (`qem_simplify::remesh` to half the vertices, mean pooling).

// candle allocates and frees a 50 MB tensor per op; glibc's allocator makes every op 2–3x
// slower here, so the benches use mimalloc, as the `meshvae` binary does.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use candle_core::{Device, Tensor, Var};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use mesh_hierarchy::{
    CsrMatrix, DepoolMode, Hierarchy, HierarchyConfig, LambdaMax, Pooler, PoolingOp, adjacency,
    normalized_laplacian, rescaled_laplacian, spirals,
};
use qem_simplify::{RemeshConfig, SimplifyConfig, remesh, simplify};
use spectral_conv::{
    Backend, ChebConv, ChebKernel, ConvDims, DePool, MaxMode, MaxPool, MeanPool, SparseKernel,
    SparseOp, SpiralConv, Workspace, locality_order, permute_symmetric,
};
use std::hint::black_box;
use std::time::Duration;

const BATCH: usize = 32;
const CHANNELS: usize = 9;

struct Graph {
    name: String,
    laplacian: CsrMatrix,
    pooling: CsrMatrix,
    depooling: CsrMatrix,
    /// Whether to run every benchmark (false: only the custom-op ones).
    full: bool,
    /// The graph-pooling and remeshing operators (elephant-gallop only).
    ablation: Option<Ablation>,
}

/// The operators of the two ablation poolings added with graph pooling.
struct Ablation {
    graph: PoolingOp,
    remesh: PoolingOp,
}

impl Ablation {
    fn build(template: &mesh_io::TriMesh) -> Self {
        let s = simplify(template, &SimplifyConfig::default()).expect("simplification");
        let graph = PoolingOp::graph(&template.faces, &s.survivors, &s.cluster_of).expect("graph");
        let r = remesh(template, &RemeshConfig::default()).expect("remeshing");
        let m = r.coarse.vertex_count();
        let remesh = PoolingOp::from_clusters(Pooler::Remesh, &r.cluster_of, m, DepoolMode::Copy)
            .expect("clusters");
        Self { graph, remesh }
    }
}

/// The set's first mesh by file name (one is enough for the connectivity), or `None` (said)
/// where the set is absent.
fn template(name: &str) -> Option<mesh_io::TriMesh> {
    let dir = mesh_io::datasets::find_or_skip(name)?;
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("data set folder")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "obj"))
        .collect();
    files.sort();
    Some(mesh_io::read_mesh(&files[0]).expect("template loads").value)
}

/// The set's template graph, and (`reorder`) the same graph renumbered in
/// `spectral_conv::locality_order` (reverse Cuthill–McKee), as a pipeline would do once.
fn load(name: &str, reorder: bool) -> Option<Graph> {
    let template = template(name)?;
    let mut adj = adjacency(template.vertex_count(), &template.faces);
    if reorder {
        let order = locality_order(&adj).expect("square");
        adj = permute_symmetric(&adj, &order).expect("a permutation");
    }
    let laplacian = rescaled_laplacian(&normalized_laplacian(&adj), LambdaMax::Two);
    let hierarchy = Hierarchy::build(&template, &HierarchyConfig::default()).expect("hierarchy");
    let op = hierarchy.pooling[0].clone();
    Some(Graph {
        name: if reorder {
            format!("{name}, RCM order")
        } else {
            name.to_string()
        },
        pooling: op.pool,
        depooling: op.depool,
        laplacian,
        full: !reorder,
        ablation: (name == "elephant-gallop" && !reorder).then(|| Ablation::build(&template)),
    })
}

fn random(shape: (usize, usize, usize), seed: u64) -> Tensor {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let n = shape.0 * shape.1 * shape.2;
    let data: Vec<f32> = (0..n)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        })
        .collect();
    Tensor::from_vec(data, shape, &Device::Cpu).expect("shape fits")
}

/// Forward then backward. With `r`, through the loss sum(r ⊙ y) (candle's multiply backward
/// also computes the unused gradient for r: about 16 extra passes over [B, V, C]); without, the
/// gradient is seeded with ones at y (`y.backward()`): the cost of the layer alone.
fn fwd_bwd(forward: impl Fn(&Tensor) -> Tensor, x: &Var, r: Option<&Tensor>) -> usize {
    let y = forward(x.as_tensor());
    let grads = match r {
        Some(r) => (y * r).and_then(|t| t.sum_all()).and_then(|l| l.backward()),
        None => y.backward(),
    }
    .expect("backward");
    black_box(grads.get(x).map(|g| g.elem_count()).unwrap_or(0))
}

fn bandwidth(c: &mut Criterion) {
    // Two threads copying a 48.7 MB [32, 42321, 9] f32 array: the machine's streaming bandwidth.
    let n = BATCH * 42_321 * CHANNELS;
    let src = vec![1.0f32; n];
    let mut dst = vec![0.0f32; n];
    let mut group = c.benchmark_group("bandwidth");
    group.throughput(Throughput::Bytes((2 * n * 4) as u64));
    group.bench_function("copy 48.7 MB, 2 threads", |b| {
        b.iter(|| {
            std::thread::scope(|s| {
                for (d, a) in dst.chunks_mut(n / 2 + 1).zip(src.chunks(n / 2 + 1)) {
                    s.spawn(move || d.copy_from_slice(a));
                }
            });
            black_box(dst[n - 1])
        })
    });
    group.finish();
}

fn conv(c: &mut Criterion) {
    let cases = [
        ("horse-gallop", false),
        ("elephant-gallop", false),
        ("elephant-gallop", true),
    ];
    for (name, reorder) in cases {
        let Some(graph) = load(name, reorder) else {
            continue;
        };
        let v = graph.laplacian.rows();
        let op = SparseOp::new(&graph.laplacian, &Device::Cpu).expect("operator");
        let weight = random((1, CHANNELS * 3, CHANNELS), 1)
            .squeeze(0)
            .expect("2-D");
        let w = Var::from_tensor(&(weight * 0.1).expect("scaled")).expect("var");
        let x = Var::from_tensor(&random((BATCH, v, CHANNELS), 2)).expect("var");
        let r = random((BATCH, v, CHANNELS), 3);
        let slow = name == "elephant-gallop";
        let wanted = |backend: Backend, fused: bool| {
            graph.full || (backend, fused) == (Backend::Kernel, true)
        };

        let mut group = c.benchmark_group(format!("conv {} ({v} vertices)", graph.name));
        group
            .sample_size(10)
            .measurement_time(Duration::from_secs(4));
        for (label, backend, fused) in [
            ("fused kernel", Backend::Kernel, true),
            ("unfused, spmm kernel", Backend::Kernel, false),
            ("unfused, fallback", Backend::Fallback, false),
        ] {
            if !wanted(backend, fused) {
                continue;
            }
            let conv =
                ChebConv::from_weights(op.with_backend(backend), 3, w.as_tensor().clone(), None)
                    .expect("layer");
            let forward = move |t: &Tensor| {
                if fused {
                    conv.forward(t)
                } else {
                    conv.forward_unfused(t)
                }
                .expect("forward")
            };
            group.bench_function(format!("cheb K=3 fwd, {label}"), |b| {
                b.iter(|| black_box(forward(x.as_tensor())))
            });
            if slow && backend == Backend::Fallback {
                group.measurement_time(Duration::from_secs(12));
            }
            group.bench_function(format!("cheb K=3 fwd+bwd, {label}"), |b| {
                b.iter(|| fwd_bwd(&forward, &x, None))
            });
            if fused {
                group.bench_function(format!("cheb K=3 fwd+bwd with loss, {label}"), |b| {
                    b.iter(|| fwd_bwd(&forward, &x, Some(&r)))
                });
            }
            group.measurement_time(Duration::from_secs(4));
        }
        // Buffer-level: the fused kernels on preallocated [V, C, B] slices.
        {
            let kernel = ChebKernel::new(&op, 3).expect("kernel");
            let d = ConvDims {
                batch: BATCH,
                c_in: CHANNELS,
                c_out: CHANNELS,
            };
            let n = v * CHANNELS * BATCH;
            let wv: Vec<f32> = w
                .as_tensor()
                .flatten_all()
                .and_then(|t| t.to_vec1())
                .expect("w");
            let xv: Vec<f32> = x
                .as_tensor()
                .flatten_all()
                .and_then(|t| t.to_vec1())
                .expect("x");
            let gv: Vec<f32> = r.flatten_all().and_then(|t| t.to_vec1()).expect("g");
            let mut terms = vec![0.0f32; kernel.terms_len(BATCH, CHANNELS)];
            let (mut y, mut dx) = (vec![0.0f32; n], vec![0.0f32; n]);
            let mut work = vec![0.0f32; kernel.work_len(BATCH, CHANNELS)];
            let mut dw = vec![0.0f32; wv.len()];
            let ws = Workspace::new();
            group.bench_function("cheb K=3 fwd, buffer-level", |b| {
                b.iter(|| {
                    kernel
                        .forward(&xv, &wv, d, &mut terms, &mut y, &ws)
                        .expect("forward");
                    black_box(y[0])
                })
            });
            group.bench_function("cheb K=3 fwd+bwd, buffer-level", |b| {
                b.iter(|| {
                    kernel
                        .forward(&xv, &wv, d, &mut terms, &mut y, &ws)
                        .expect("forward");
                    let bufs = Some((dx.as_mut_slice(), work.as_mut_slice()));
                    kernel
                        .backward(&xv, &terms, &wv, &gv, d, &mut dw, bufs, &ws)
                        .expect("backward");
                    black_box(dx[0])
                })
            });
            if graph.full {
                let pool = SparseKernel::new(
                    MeanPool::new(&graph.pooling, &Device::Cpu)
                        .expect("pool")
                        .op(),
                );
                let coarse_n = graph.pooling.rows() * CHANNELS * BATCH;
                let (mut py, mut back) = (vec![0.0f32; coarse_n], vec![0.0f32; n]);
                group.bench_function("mean pool fwd+bwd, buffer-level", |b| {
                    b.iter(|| {
                        pool.apply(&xv, &mut py, CHANNELS * BATCH).expect("pool");
                        pool.apply_t(&py, &mut back, CHANNELS * BATCH)
                            .expect("adjoint");
                        black_box(back[0])
                    })
                });
            }
            if let Some(ablation) = &graph.ablation {
                buffer_level_ablation(&mut group, ablation, &xv);
            }
        }
        // The vertex-major layout [V, B, C] a network keeps throughout (no transposes).
        let x_vm = Var::from_tensor(&random((v, BATCH, CHANNELS), 2)).expect("var");
        let conv_vm =
            ChebConv::from_weights(op.clone(), 3, w.as_tensor().clone(), None).expect("layer");
        let forward_vm = move |t: &Tensor| conv_vm.forward_vertex_major(t).expect("forward");
        group.bench_function("cheb K=3 fwd, fused kernel, vertex-major", |b| {
            b.iter(|| black_box(forward_vm(x_vm.as_tensor())))
        });
        group.bench_function("cheb K=3 fwd+bwd, fused kernel, vertex-major", |b| {
            b.iter(|| fwd_bwd(&forward_vm, &x_vm, None))
        });
        for (label, backend) in [
            ("custom op", Backend::Kernel),
            ("fallback", Backend::Fallback),
        ] {
            if !wanted(backend, true) {
                continue;
            }
            let op = op.with_backend(backend);
            let apply = move |t: &Tensor| op.apply(t).expect("product");
            group.bench_function(format!("L x fwd, {label}"), |b| {
                b.iter(|| black_box(apply(x.as_tensor())))
            });
            if slow && backend == Backend::Fallback {
                group.measurement_time(Duration::from_secs(10));
            }
            group.bench_function(format!("L x fwd+bwd, {label}"), |b| {
                b.iter(|| fwd_bwd(&apply, &x, None))
            });
            group.bench_function(format!("L x fwd+bwd with loss, {label}"), |b| {
                b.iter(|| fwd_bwd(&apply, &x, Some(&r)))
            });
            group.measurement_time(Duration::from_secs(4));
        }

        if !graph.full {
            group.finish();
            continue;
        }
        let pool = MeanPool::new(&graph.pooling, &Device::Cpu).expect("pool");
        let depool = DePool::new(&graph.depooling, &Device::Cpu).expect("de-pool");
        let coarse_v = graph.pooling.rows();
        let coarse = Var::from_tensor(&random((BATCH, coarse_v, CHANNELS), 4)).expect("var");
        let pool_fwd = |t: &Tensor| pool.forward(t).expect("pool");
        let depool_fwd = |t: &Tensor| depool.forward(t).expect("de-pool");
        group.bench_function(format!("mean pool {v}->{coarse_v} fwd"), |b| {
            b.iter(|| black_box(pool_fwd(x.as_tensor())))
        });
        group.bench_function(format!("mean pool {v}->{coarse_v} fwd+bwd"), |b| {
            b.iter(|| fwd_bwd(pool_fwd, &x, None))
        });
        group.bench_function(format!("de-pool {coarse_v}->{v} fwd"), |b| {
            b.iter(|| black_box(depool_fwd(coarse.as_tensor())))
        });
        group.bench_function(format!("de-pool {coarse_v}->{v} fwd+bwd"), |b| {
            b.iter(|| fwd_bwd(depool_fwd, &coarse, None))
        });
        let coarse_vm = Var::from_tensor(&random((coarse_v, BATCH, CHANNELS), 4)).expect("var");
        let pool_vm = |t: &Tensor| pool.forward_vertex_major(t).expect("pool");
        let depool_vm = |t: &Tensor| depool.forward_vertex_major(t).expect("de-pool");
        group.bench_function(
            format!("mean pool {v}->{coarse_v} fwd, vertex-major"),
            |b| b.iter(|| black_box(pool_vm(x_vm.as_tensor()))),
        );
        group.bench_function(
            format!("mean pool {v}->{coarse_v} fwd+bwd, vertex-major"),
            |b| b.iter(|| fwd_bwd(pool_vm, &x_vm, None)),
        );
        group.bench_function(format!("de-pool {coarse_v}->{v} fwd, vertex-major"), |b| {
            b.iter(|| black_box(depool_vm(coarse_vm.as_tensor())))
        });
        group.bench_function(
            format!("de-pool {coarse_v}->{v} fwd+bwd, vertex-major"),
            |b| b.iter(|| fwd_bwd(depool_vm, &coarse_vm, None)),
        );
        if let Some(ablation) = &graph.ablation {
            candle_ablation(&mut group, ablation, &x, &x_vm);
        }
        group.finish();
    }
}

type Group<'a> = criterion::BenchmarkGroup<'a, criterion::measurement::WallTime>;

/// Graph max pooling, its de-pooling and remeshing's mean pooling as candle ops, batch-major
/// and vertex-major, forward + backward (the gradient seeded with ones).
fn candle_ablation(group: &mut Group<'_>, ablation: &Ablation, x: &Var, x_vm: &Var) {
    let dev = Device::Cpu;
    let (graph, remeshed) = (&ablation.graph, &ablation.remesh);
    let v = graph.fine_count();
    let (m, mr) = (graph.coarse_count(), remeshed.coarse_count());
    let max = MaxPool::with_mode(&graph.pool, MaxMode::PlainMax, &dev).expect("graph pool");
    let up = DePool::new(&graph.depool, &dev).expect("graph de-pool");
    let mean = MeanPool::new(&remeshed.pool, &dev).expect("remesh pool");
    let coarse_vm = Var::from_tensor(&random((m, BATCH, CHANNELS), 5)).expect("var");
    let max_fwd = |t: &Tensor| max.forward(t).expect("pool");
    let max_vm = |t: &Tensor| max.forward_vertex_major(t).expect("pool");
    let up_vm = |t: &Tensor| up.forward_vertex_major(t).expect("de-pool");
    let mean_fwd = |t: &Tensor| mean.forward(t).expect("pool");
    let mean_vm = |t: &Tensor| mean.forward_vertex_major(t).expect("pool");
    group.bench_function(format!("graph pool {v}->{m} fwd"), |b| {
        b.iter(|| black_box(max_fwd(x.as_tensor())))
    });
    group.bench_function(format!("graph pool {v}->{m} fwd+bwd"), |b| {
        b.iter(|| fwd_bwd(max_fwd, x, None))
    });
    group.bench_function(format!("graph pool {v}->{m} fwd+bwd, vertex-major"), |b| {
        b.iter(|| fwd_bwd(max_vm, x_vm, None))
    });
    group.bench_function(
        format!("graph de-pool {m}->{v} fwd+bwd, vertex-major"),
        |b| b.iter(|| fwd_bwd(up_vm, &coarse_vm, None)),
    );
    group.bench_function(format!("remesh pool {v}->{mr} fwd+bwd"), |b| {
        b.iter(|| fwd_bwd(mean_fwd, x, None))
    });
    group.bench_function(
        format!("remesh pool {v}->{mr} fwd+bwd, vertex-major"),
        |b| b.iter(|| fwd_bwd(mean_vm, x_vm, None)),
    );
}

/// The same three on caller-owned `[V, C, B]` slices, as the training engine runs them.
fn buffer_level_ablation(group: &mut Group<'_>, ablation: &Ablation, xv: &[f32]) {
    let dev = Device::Cpu;
    let n = CHANNELS * BATCH;
    let graph = &ablation.graph;
    let (v, m) = (graph.fine_count(), graph.coarse_count());
    let max = MaxPool::with_mode(&graph.pool, MaxMode::PlainMax, &dev).expect("graph pool");
    let up = SparseKernel::new(DePool::new(&graph.depool, &dev).expect("de-pool").op());
    let (mut y, mut arg, mut dx) = (vec![0.0f32; m * n], vec![0u32; m * n], vec![0.0f32; v * n]);
    group.bench_function("graph pool fwd+bwd, buffer-level", |b| {
        b.iter(|| {
            max.kernel()
                .forward_into(xv, &mut y, &mut arg, n)
                .expect("pool");
            max.kernel()
                .backward_into(&arg, &y, &mut dx, n)
                .expect("adjoint");
            black_box(dx[0])
        })
    });
    group.bench_function("graph de-pool fwd+bwd, buffer-level", |b| {
        b.iter(|| {
            up.apply(&y, &mut dx, n).expect("de-pool");
            up.apply_t(&dx, &mut y, n).expect("adjoint");
            black_box(y[0])
        })
    });
    let remeshed = &ablation.remesh;
    let mean = SparseKernel::new(MeanPool::new(&remeshed.pool, &dev).expect("pool").op());
    let mut yr = vec![0.0f32; remeshed.coarse_count() * n];
    group.bench_function("remesh pool fwd+bwd, buffer-level", |b| {
        b.iter(|| {
            mean.apply(xv, &mut yr, n).expect("pool");
            mean.apply_t(&yr, &mut dx, n).expect("adjoint");
            black_box(dx[0])
        })
    });
}

/// SpiralNet++'s costliest layer: spirals of 9 on horse-gallop's template, 32 → 32 channels.
fn spiral(c: &mut Criterion) {
    let Some(template) = template("horse-gallop") else {
        return;
    };
    let (length, channels) = (9, 32);
    let s = spirals(&template.positions, &template.faces, length, 1).expect("spirals");
    let v = template.vertex_count();
    let weight = random((1, length * channels, channels), 4)
        .squeeze(0)
        .expect("2-D");
    let w = Var::from_tensor(&(weight * 0.05).expect("scaled")).expect("var");
    let x = Var::from_tensor(&random((BATCH, v, channels), 5)).expect("var");
    let mut group = c.benchmark_group(format!("spiral conv horse-gallop ({v} vertices)"));
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(4));
    for (label, backend) in [("kernel", Backend::Kernel), ("fallback", Backend::Fallback)] {
        let conv = SpiralConv::from_weights(&s.indices, length, w.as_tensor().clone(), None)
            .expect("layer")
            .with_backend(backend);
        let forward = move |t: &Tensor| conv.forward(t).expect("forward");
        group.bench_function(format!("S=9, 32->32 fwd, {label}"), |b| {
            b.iter(|| black_box(forward(x.as_tensor())))
        });
        group.bench_function(format!("S=9, 32->32 fwd+bwd, {label}"), |b| {
            b.iter(|| fwd_bwd(&forward, &x, None))
        });
    }
    group.finish();
}

criterion_group!(benches, bandwidth, conv, spiral);
criterion_main!(benches);
