//! Acceptance tests of the two ablation poolers added last: graph max pooling (operators
//! against a dense reference built from the simplifier's output, coverage, gradients against
//! central differences, files) and uniform remeshing (mean pooling over its clusters). The
//! hand-checked tiny mesh of graph pooling is in `src/graph.rs`.

mod common;

use common::*;
use mesh_hierarchy::{DepoolMode, Hierarchy, HierarchyConfig, Pooler};
use qem_simplify::shapes::{bumpy_grid, icosphere, torus};
use qem_simplify::{RemeshConfig, SimplifyConfig, remesh, simplify};

#[test]
fn graph_pooling_keeps_our_coarse_levels_and_covers_every_vertex() {
    for mesh in meshes() {
        let ours = Hierarchy::build(&mesh, &config(Pooler::Mean, 2)).unwrap();
        let graph = Hierarchy::build(&mesh, &config(Pooler::Graph, 2)).unwrap();
        assert!(graph.check_shapes().is_ok());
        assert_eq!(graph.levels, ours.levels);
        for (op, mean) in graph.pooling.iter().zip(&ours.pooling) {
            assert_eq!(op.kind, Pooler::Graph);
            assert_eq!(op.clusters, mean.clusters);
            let (n, m) = (op.fine_count(), op.coarse_count());
            let mut covers = vec![0usize; n];
            for &u in op.pool.indices() {
                covers[u as usize] += 1;
            }
            assert!(covers.iter().all(|&k| k >= 1), "a fine vertex in no N(c)");
            // The neighbourhoods overlap: on average a vertex is in several.
            assert!(
                op.pool.nnz() > 2 * n,
                "{} memberships of {n}",
                op.pool.nnz()
            );
            for c in 0..m {
                let (cols, vals) = op.pool.row(c);
                assert!(
                    vals.iter()
                        .all(|&w| (w - 1.0 / cols.len() as f64).abs() < 1e-15)
                );
            }
            for (v, &k) in covers.iter().enumerate() {
                let (cols, vals) = op.depool.row(v);
                assert_eq!(cols.len(), k);
                assert!((vals.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            }
        }
    }
}

#[test]
fn graph_operators_equal_a_dense_reference() {
    let mesh = icosphere(2);
    let h = Hierarchy::build(&mesh, &config(Pooler::Graph, 1)).unwrap();
    let s = simplify(&mesh, &SimplifyConfig::default()).unwrap();
    let (n, m) = (mesh.vertex_count(), s.survivors.len());
    // Dense adjacency straight from the faces.
    let mut adj = vec![vec![false; n]; n];
    for f in &mesh.faces {
        for k in 0..3 {
            let (a, b) = (f[k] as usize, f[(k + 1) % 3] as usize);
            adj[a][b] = true;
            adj[b][a] = true;
        }
    }
    let member: Vec<Vec<bool>> = (0..m)
        .map(|c| {
            let sc = s.survivors[c] as usize;
            (0..n)
                .map(|u| u == sc || adj[sc][u] || s.cluster_of[u] as usize == c)
                .collect()
        })
        .collect();
    let size: Vec<f64> = member
        .iter()
        .map(|r| r.iter().filter(|&&b| b).count() as f64)
        .collect();
    let covers: Vec<f64> = (0..n)
        .map(|u| (0..m).filter(|&c| member[c][u]).count() as f64)
        .collect();
    let op = &h.pooling[0];
    let (p, d) = (op.pool.to_dense(), op.depool.to_dense());
    for c in 0..m {
        for u in 0..n {
            let (wp, wd) = if member[c][u] {
                (1.0 / size[c], 1.0 / covers[u])
            } else {
                (0.0, 0.0)
            };
            assert_eq!(p[c][u], wp, "P[{c}, {u}]");
            assert_eq!(d[u][c], wd, "D[{u}, {c}]");
        }
    }
    // The max pooling and de-pooling against brute force over the dense membership.
    let channels = 3;
    let x = distinct_field(n * channels);
    let y = op.pool(&x, channels).unwrap();
    for c in 0..m {
        for k in 0..channels {
            let want = (0..n)
                .filter(|&u| member[c][u])
                .map(|u| x[u * channels + k])
                .fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(y[c * channels + k], want);
        }
    }
    let coarse = distinct_field(m * channels);
    let up = op.depool(&coarse, channels).unwrap();
    for u in 0..n {
        for k in 0..channels {
            let sum: f64 = (0..m)
                .filter(|&c| member[c][u])
                .map(|c| coarse[c * channels + k])
                .sum();
            assert!((up[u * channels + k] - sum / covers[u]).abs() < 1e-12);
        }
    }
}

#[test]
fn graph_pooling_gradients_match_central_differences() {
    let mesh = torus(12, 8, 1.0, 0.3);
    let h = Hierarchy::build(&mesh, &config(Pooler::Graph, 1)).unwrap();
    let op = &h.pooling[0];
    let channels = 2;
    let x = distinct_field(op.fine_count() * channels);
    let g = field(op.coarse_count(), channels);
    let want = central_differences(|x| op.pool(x, channels).unwrap(), &x, &g, 1e-7);
    let got = op.pool_gradient(&x, &g, channels).unwrap();
    assert!(close(&got, &want, 1e-6));
    // Vertices selected by several neighbourhoods receive summed gradients.
    let selected = got.iter().zip(&want).filter(|(a, _)| **a != 0.0).count();
    assert!(selected > 0 && selected < op.coarse_count() * channels);
    // De-pooling is linear: its gradient is Dᵀ g.
    let coarse = distinct_field(op.coarse_count() * channels);
    let gf = field(op.fine_count(), channels);
    let want = central_differences(|c| op.depool(c, channels).unwrap(), &coarse, &gf, 1e-6);
    let dt = op.depool.transpose();
    let got: Vec<f64> = (0..op.coarse_count() * channels)
        .map(|i| {
            let (cols, vals) = dt.row(i / channels);
            cols.iter()
                .zip(vals)
                .map(|(&u, &w)| w * gf[u as usize * channels + i % channels])
                .sum()
        })
        .collect();
    assert!(close(&got, &want, 1e-6));
    assert!(op.pool_gradient(&x, &g[1..], channels).is_err());
}

#[test]
fn graph_hierarchy_saves_and_loads_and_a_broken_one_is_refused() {
    let h = Hierarchy::build(&icosphere(2), &config(Pooler::Graph, 2)).unwrap();
    let path = temp_path("graph.hierarchy");
    h.save(&path).unwrap();
    let back = Hierarchy::load(&path).unwrap();
    assert_eq!(back.pooling, h.pooling);
    assert_eq!(back.config.pooler, Pooler::Graph);
    // A neighbourhood emptied in a (version-1, JSON) file: the loader refuses it.
    write_json_v1(&h, &path);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    let pool = &mut value["hierarchy"]["pooling"][1]["pool"];
    let first = pool["indptr"][1].as_u64().unwrap() as usize;
    let rows = pool["indptr"].as_array().unwrap().len();
    for r in 1..rows {
        let p = pool["indptr"][r].as_u64().unwrap() as usize;
        pool["indptr"][r] = serde_json::json!(p - first);
    }
    for key in ["indices", "values"] {
        let list = pool[key].as_array_mut().unwrap();
        list.drain(..first);
    }
    std::fs::write(&path, value.to_string()).unwrap();
    let err = Hierarchy::load(&path).unwrap_err();
    assert!(err.to_string().contains("neighbourhood"), "{err}");
    let _ = std::fs::remove_file(&path);
}

#[test]
fn remesh_operators_are_mean_pooling_over_the_remeshing_clusters() {
    for mesh in meshes() {
        for mode in [DepoolMode::Copy, DepoolMode::Transpose] {
            let cfg = HierarchyConfig {
                depool: mode,
                ..config(Pooler::Remesh, 1)
            };
            let h = Hierarchy::build(&mesh, &cfg).unwrap();
            assert!(h.check_shapes().is_ok());
            let r = remesh(&mesh, &RemeshConfig::default()).unwrap();
            let m = r.coarse.vertex_count();
            assert_eq!(h.vertex_counts(), vec![mesh.vertex_count(), m]);
            assert_eq!(h.levels[1].positions, r.coarse.positions);
            assert_eq!(h.levels[1].faces, r.coarse.faces);
            let op = &h.pooling[0];
            assert_eq!(op.kind, Pooler::Remesh);
            let [p, d] = dense_reference(&r.cluster_of, m, mode);
            assert_eq!(op.pool.to_dense(), p);
            assert_eq!(op.depool.to_dense(), d);
            // Every fine vertex is in exactly one cluster.
            let mut covers = vec![0; mesh.vertex_count()];
            op.pool
                .indices()
                .iter()
                .for_each(|&u| covers[u as usize] += 1);
            assert!(covers.iter().all(|&k| k == 1));
        }
    }
}

#[test]
fn remesh_pooling_gradients_match_central_differences() {
    let mesh = bumpy_grid(12, 10);
    let h = Hierarchy::build(&mesh, &config(Pooler::Remesh, 1)).unwrap();
    let op = &h.pooling[0];
    let channels = 2;
    let x = distinct_field(op.fine_count() * channels);
    // Positive upstream values, so that every fine vertex's gradient is non-zero.
    let g: Vec<f64> = distinct_field(op.coarse_count() * channels)
        .iter()
        .map(|v| v + 2.0)
        .collect();
    let want = central_differences(|x| op.pool(x, channels).unwrap(), &x, &g, 1e-6);
    let got = op.pool_gradient(&x, &g, channels).unwrap();
    assert!(close(&got, &want, 1e-8));
    assert!(
        got.iter().all(|&v| v != 0.0),
        "every fine vertex gets a gradient"
    );
}
