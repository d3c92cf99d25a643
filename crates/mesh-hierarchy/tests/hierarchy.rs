//! Acceptance tests of the hierarchy: operators against dense references built here from the
//! simplifier's `cluster_of`, composition of two levels, Laplacians (files: `file.rs`).

mod common;

use common::*;
use mesh_hierarchy::sampling::closest_on_triangle;
use mesh_hierarchy::{
    DepoolMode, Hierarchy, HierarchyConfig, HierarchyError, LambdaMax, Pooler, normalized_laplacian,
};
use mesh_io::TriMesh;
use qem_simplify::shapes::{bumpy_grid, icosphere, torus};
use qem_simplify::{SimplifyConfig, Target, simplify};

#[test]
fn constant_fields_survive_every_pooler() {
    for mesh in meshes() {
        for pooler in Pooler::ALL {
            let h = Hierarchy::build(&mesh, &config(pooler, 2)).unwrap();
            for op in &h.pooling {
                let ones = vec![3.5; op.fine_count() * 2];
                assert!(close(
                    &op.pool(&ones, 2).unwrap(),
                    &vec![3.5; op.coarse_count() * 2],
                    1e-12
                ));
                let up = op.depool(&vec![3.5; op.coarse_count() * 2], 2).unwrap();
                assert!(close(&up, &ones, 1e-12), "{pooler}");
            }
        }
    }
}

#[test]
fn mean_pool_after_copy_depool_is_identity() {
    for mesh in meshes() {
        for pooler in [
            Pooler::Mean,
            Pooler::Qem,
            Pooler::Max,
            Pooler::None,
            Pooler::Remesh,
        ] {
            let h = Hierarchy::build(&mesh, &config(pooler, 2)).unwrap();
            for op in &h.pooling {
                let x = field(op.coarse_count(), 3);
                assert!(
                    close(&op.pool(&op.depool(&x, 3).unwrap(), 3).unwrap(), &x, 1e-12),
                    "{pooler}"
                );
            }
        }
    }
}

#[test]
fn sparse_operators_equal_dense_reference() {
    let mesh = icosphere(2);
    for (pooler, lambda) in [
        (Pooler::Mean, qem_simplify::DEFAULT_LAMBDA),
        (Pooler::Qem, 0.0),
    ] {
        for mode in [DepoolMode::Copy, DepoolMode::Transpose] {
            let cfg = HierarchyConfig {
                depool: mode,
                ..config(pooler, 1)
            };
            let h = Hierarchy::build(&mesh, &cfg).unwrap();
            let s = simplify(
                &mesh,
                &SimplifyConfig {
                    target: Target::Ratio(0.5),
                    lambda,
                },
            )
            .unwrap();
            let [p, d] = dense_reference(&s.cluster_of, s.survivors.len(), mode);
            assert_eq!(h.pooling[0].pool.to_dense(), p);
            assert_eq!(h.pooling[0].depool.to_dense(), d);
            assert_eq!(h.levels[1].positions, s.coarse.positions);
        }
    }
    // Sampling: the selection matrix picks the survivors.
    let h = Hierarchy::build(&mesh, &config(Pooler::Sampling, 1)).unwrap();
    let s = simplify(
        &mesh,
        &SimplifyConfig {
            target: Target::Ratio(0.5),
            lambda: 0.0,
        },
    )
    .unwrap();
    let x = field(mesh.vertex_count(), 1);
    let want: Vec<f64> = s.survivors.iter().map(|&v| x[v as usize]).collect();
    assert_eq!(h.pooling[0].pool(&x, 1).unwrap(), want);
}

#[test]
fn two_level_hierarchies_compose() {
    let mesh = torus(16, 10, 1.0, 0.35);
    let h = Hierarchy::build(&mesh, &config(Pooler::Mean, 2)).unwrap();
    let cfg = SimplifyConfig::default();
    let s1 = simplify(&mesh, &cfg).unwrap();
    let s2 = simplify(&s1.coarse, &cfg).unwrap();
    assert_eq!(h.vertex_counts(), vec![160, 80, 40]);
    let x = field(160, 1);
    // Mean of the level-1 means over each level-2 cluster, straight from the two maps.
    let mean = |values: &[f64], cluster_of: &[u32], m: usize| {
        let mut sum = vec![0.0; m];
        let mut count = vec![0.0; m];
        for (v, &c) in cluster_of.iter().enumerate() {
            sum[c as usize] += values[v];
            count[c as usize] += 1.0;
        }
        sum.iter()
            .zip(&count)
            .map(|(s, c)| s / c)
            .collect::<Vec<f64>>()
    };
    let want = mean(&mean(&x, &s1.cluster_of, 80), &s2.cluster_of, 40);
    let got = h.pooling[1]
        .pool(&h.pooling[0].pool(&x, 1).unwrap(), 1)
        .unwrap();
    assert!(close(&got, &want, 1e-12));
    // De-pooling twice copies level-2 values along the cluster-of-cluster map.
    let y = field(40, 1);
    let up = h.pooling[0]
        .depool(&h.pooling[1].depool(&y, 1).unwrap(), 1)
        .unwrap();
    let want: Vec<f64> = (0..160)
        .map(|v| y[s2.cluster_of[s1.cluster_of[v] as usize] as usize])
        .collect();
    assert_eq!(up, want);
}

#[test]
fn laplacians_match_dense_formula_on_every_level() {
    for lambda_max in [LambdaMax::Two, LambdaMax::PowerIteration(200)] {
        let cfg = HierarchyConfig {
            lambda_max,
            ..config(Pooler::Mean, 2)
        };
        let h = Hierarchy::build(&bumpy_grid(9, 9), &cfg).unwrap();
        for level in &h.levels {
            let n = level.vertex_count;
            let mut a = vec![vec![0.0; n]; n];
            for f in &level.faces {
                for k in 0..3 {
                    let (i, j) = (f[k] as usize, f[(k + 1) % 3] as usize);
                    a[i][j] = 1.0;
                    a[j][i] = 1.0;
                }
            }
            let deg: Vec<f64> = a.iter().map(|r| r.iter().sum()).collect();
            let lmax = match lambda_max {
                LambdaMax::Two => 2.0,
                LambdaMax::PowerIteration(k) => {
                    let sparse = mesh_hierarchy::adjacency(n, &level.faces);
                    mesh_hierarchy::laplacian::largest_eigenvalue(&normalized_laplacian(&sparse), k)
                }
            };
            assert!(lmax > 1.0 && lmax <= 2.0 + 1e-9, "{lmax}");
            let got = level.laplacian.to_dense();
            for i in 0..n {
                for j in 0..n {
                    let eye = if i == j { 1.0 } else { 0.0 };
                    let l = eye - a[i][j] / (deg[i] * deg[j]).sqrt();
                    assert!((got[i][j] - (2.0 * l / lmax - eye)).abs() < 1e-12);
                }
            }
        }
    }
}

#[test]
fn sampling_upsamples_from_the_nearest_coarse_triangle() {
    for mesh in meshes() {
        let h = Hierarchy::build(&mesh, &config(Pooler::Sampling, 1)).unwrap();
        let (fine, coarse) = (&h.levels[0], &h.levels[1]);
        let up = &h.pooling[0].depool;
        let mut worse = 0;
        for v in 0..fine.vertex_count {
            let (cols, w) = up.row(v);
            assert!(w.iter().all(|&x| x >= -1e-12));
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            let p = fine.positions[v].map(f64::from);
            let q: [f64; 3] = std::array::from_fn(|k| {
                cols.iter()
                    .zip(w)
                    .map(|(&c, &wc)| wc * f64::from(coarse.positions[c as usize][k]))
                    .sum()
            });
            let d2: f64 = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum();
            let best = coarse
                .faces
                .iter()
                .map(|f| {
                    closest_on_triangle(p, f.map(|i| coarse.positions[i as usize].map(f64::from))).0
                })
                .fold(f64::INFINITY, f64::min);
            assert!(d2 >= best - 1e-12);
            if d2 > best + 1e-9 {
                worse += 1;
            }
        }
        // The local search finds the global nearest triangle for (nearly) every vertex.
        assert!(
            worse * 100 <= fine.vertex_count,
            "{worse} of {}",
            fine.vertex_count
        );
    }
}

#[test]
fn no_pooling_repeats_the_template() {
    let mesh = icosphere(1);
    let h = Hierarchy::build(&mesh, &config(Pooler::None, 2)).unwrap();
    assert_eq!(h.vertex_counts(), vec![42, 42, 42]);
    assert_eq!(h.levels[0], h.levels[2]);
    let x = field(42, 2);
    assert_eq!(h.pooling[1].pool(&x, 2).unwrap(), x);
    assert_eq!(h.pooling[1].depool(&x, 2).unwrap(), x);
}

#[test]
fn bad_configuration_is_a_typed_error() {
    let mesh = icosphere(1);
    for ratio in [0.0, 1.5, f64::NAN] {
        let cfg = HierarchyConfig {
            ratio,
            ..Default::default()
        };
        assert!(matches!(
            Hierarchy::build(&mesh, &cfg),
            Err(HierarchyError::InvalidArgument {
                argument: "ratio",
                ..
            })
        ));
    }
    let broken = TriMesh {
        positions: mesh.positions.clone(),
        faces: vec![[0, 1, 99]],
    };
    assert!(matches!(
        Hierarchy::build(&broken, &Default::default()),
        Err(HierarchyError::MeshIo(_))
    ));
}

#[test]
fn horse_gallop_template_builds_one_level() {
    let Some(dir) = mesh_io::datasets::find_or_skip("horse-gallop") else {
        return;
    };
    let set = mesh_io::load_set(&dir).unwrap().value;
    let template = set.template();
    for pooler in [
        Pooler::Mean,
        Pooler::Sampling,
        Pooler::Graph,
        Pooler::Remesh,
    ] {
        let h = Hierarchy::build(&template, &config(pooler, 1)).unwrap();
        assert_eq!(h.vertex_counts(), vec![8431, 4216], "{pooler}");
        assert!(h.check_shapes().is_ok());
        let ones = vec![1.0; 4216];
        assert!(close(
            &h.pooling[0].depool(&ones, 1).unwrap(),
            &vec![1.0; 8431],
            1e-12
        ));
    }
}
