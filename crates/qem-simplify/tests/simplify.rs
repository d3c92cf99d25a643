//! The simplifier on meshes generated in code: topology kept, exact counts, complete map,
//! connected clusters, determinism, typed errors on bad input.

mod common;

use mesh_io::TriMesh;
use qem_simplify::shapes::{bumpy_grid, icosphere, torus};
use qem_simplify::{
    SimplifyConfig, SimplifyError, Target, UniformityReport, geometric_error_rel, simplify,
};

fn config(target: Target, lambda: f64) -> SimplifyConfig {
    SimplifyConfig { target, lambda }
}

#[test]
fn sphere_torus_and_open_grid_at_half_for_both_lambdas() {
    let meshes = [
        ("icosphere", icosphere(3)),
        ("torus", torus(40, 16, 1.0, 0.35)),
        ("grid", bumpy_grid(30, 24)),
    ];
    for (name, mesh) in meshes {
        for lambda in [0.0, 0.001, 0.05] {
            let s = simplify(&mesh, &config(Target::Ratio(0.5), lambda))
                .unwrap_or_else(|e| panic!("{name} lambda={lambda}: {e}"));
            common::check_simplified(&mesh, &s, mesh.vertex_count().div_ceil(2));
        }
    }
}

#[test]
fn deep_reductions_keep_topology() {
    let sphere = icosphere(3); // 642 vertices
    let s = simplify(&sphere, &config(Target::Vertices(40), 0.001)).unwrap();
    common::check_simplified(&sphere, &s, 40);
    let torus = torus(30, 12, 1.0, 0.4); // 360 vertices, genus 1
    let s = simplify(&torus, &config(Target::Ratio(0.15), 0.001)).unwrap();
    common::check_simplified(&torus, &s, 54);
    let grid = bumpy_grid(20, 20);
    let s = simplify(&grid, &config(Target::Ratio(0.2), 0.0)).unwrap();
    common::check_simplified(&grid, &s, 80);
}

#[test]
fn repeated_levels_like_a_hierarchy() {
    let mut mesh = icosphere(4); // 2562 vertices
    for _ in 0..4 {
        let s = simplify(&mesh, &SimplifyConfig::default()).unwrap();
        common::check_simplified(&mesh, &s, mesh.vertex_count().div_ceil(2));
        mesh = s.coarse;
    }
    assert_eq!(mesh.vertex_count(), 161);
}

#[test]
fn same_input_same_output() {
    let mesh = torus(36, 14, 1.0, 0.3);
    let a = simplify(&mesh, &SimplifyConfig::default()).unwrap();
    let b = simplify(&mesh, &SimplifyConfig::default()).unwrap();
    assert_eq!(a, b);
    // On a perfectly regular torus many costs tie: only the total order decides.
    let c = simplify(&mesh, &config(Target::Ratio(0.5), 0.0)).unwrap();
    let d = simplify(&mesh, &config(Target::Ratio(0.5), 0.0)).unwrap();
    assert_eq!(c, d);
}

#[test]
fn same_output_on_any_number_of_threads() {
    // Large enough for several topology ranges and several batches of initial costs.
    for mesh in [icosphere(5), bumpy_grid(100, 90)] {
        for lambda in [0.0, 0.001] {
            let run = |threads| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .expect("thread pool")
                    .install(|| simplify(&mesh, &config(Target::Ratio(0.5), lambda)))
                    .expect("simplifies")
            };
            assert_eq!(run(1), run(3), "lambda={lambda}");
        }
    }
}

#[test]
fn target_equal_to_the_input_changes_nothing() {
    let mesh = icosphere(1);
    let s = simplify(&mesh, &config(Target::Ratio(1.0), 0.001)).unwrap();
    assert_eq!(s.coarse, mesh);
    assert_eq!(
        s.cluster_of,
        (0..mesh.vertex_count() as u32).collect::<Vec<_>>()
    );
}

#[test]
fn result_is_independent_of_scale() {
    // Lengths and quadrics are measured on the unit-diagonal mesh: a copy scaled by a power of
    // two (exact in floating point) gives the very same contractions.
    let mesh = bumpy_grid(16, 16);
    let scaled = TriMesh {
        positions: mesh
            .positions
            .iter()
            .map(|p| p.map(|x| x * 256.0))
            .collect(),
        faces: mesh.faces.clone(),
    };
    let a = simplify(&mesh, &SimplifyConfig::default()).unwrap();
    let b = simplify(&scaled, &SimplifyConfig::default()).unwrap();
    assert_eq!(a.cluster_of, b.cluster_of);
    assert_eq!(a.coarse.faces, b.coarse.faces);
    for (p, q) in a.coarse.positions.iter().zip(&b.coarse.positions) {
        for k in 0..3 {
            assert!((p[k] * 256.0 - q[k]).abs() <= 1e-4 * 256.0);
        }
    }
}

#[test]
fn length_term_evens_out_edges_on_an_uneven_mesh() {
    // A sphere whose sampling is dense near one pole: the length term must make the coarse
    // edges more even than classical QEM does, at a small geometric error.
    let mut mesh = icosphere(4);
    for p in &mut mesh.positions {
        // Pull vertices towards z = 1, then back onto the sphere.
        let t = 0.5 * (1.0 + p[2]);
        let q = [
            p[0] * (1.0 - 0.6 * t),
            p[1] * (1.0 - 0.6 * t),
            p[2] + 0.6 * t,
        ];
        let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
        *p = q.map(|x| x / n);
    }
    let classical = simplify(&mesh, &config(Target::Ratio(0.5), 0.0)).unwrap();
    let even = simplify(&mesh, &SimplifyConfig::default()).unwrap();
    let (r0, r1) = (
        UniformityReport::of(&mesh, &classical),
        UniformityReport::of(&mesh, &even),
    );
    assert!(r1.edge_cv < r0.edge_cv, "{} vs {}", r1.edge_cv, r0.edge_cv);
    let (e0, e1) = (
        geometric_error_rel(&mesh, &classical.coarse),
        geometric_error_rel(&mesh, &even.coarse),
    );
    assert!(e1 < 1e-2 && e0 < 1e-2, "{e0} {e1}");
}

#[test]
fn bad_input_is_a_typed_error() {
    let sphere = icosphere(1);
    let bad = |target, lambda| simplify(&sphere, &config(target, lambda)).unwrap_err();
    assert!(matches!(
        bad(Target::Ratio(0.0), 0.001),
        SimplifyError::InvalidArgument {
            argument: "ratio",
            ..
        }
    ));
    assert!(matches!(
        bad(Target::Ratio(f64::NAN), 0.001),
        SimplifyError::InvalidArgument {
            argument: "ratio",
            ..
        }
    ));
    assert!(matches!(
        bad(Target::Vertices(1000), 0.001),
        SimplifyError::InvalidArgument {
            argument: "target",
            ..
        }
    ));
    assert!(matches!(
        bad(Target::Ratio(0.5), -1.0),
        SimplifyError::InvalidArgument {
            argument: "lambda",
            ..
        }
    ));
    // Three faces on one edge.
    let fin = TriMesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
        ],
        faces: vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
    };
    let err = simplify(&fin, &SimplifyConfig::default()).unwrap_err();
    assert!(matches!(err, SimplifyError::NonManifold(_)), "{err}");
    assert!(err.to_string().contains("edge (0, 1)"), "{err}");
    // Out-of-range index: mesh-io's own validation error.
    let broken = TriMesh {
        positions: vec![[0.0; 3]; 3],
        faces: vec![[0, 1, 7]],
    };
    assert!(matches!(
        simplify(&broken, &SimplifyConfig::default()).unwrap_err(),
        SimplifyError::MeshIo(_)
    ));
    // All vertices at one point.
    let point = TriMesh {
        positions: vec![[1.0; 3]; 3],
        faces: vec![[0, 1, 2]],
    };
    assert!(matches!(
        simplify(&point, &SimplifyConfig::default()).unwrap_err(),
        SimplifyError::ZeroExtent { vertices: 3 }
    ));
}

#[test]
fn an_unreachable_target_is_reported_not_faked() {
    // A tetrahedron cannot lose a vertex and stay a closed 2-manifold.
    let tetra = TriMesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ],
        faces: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]],
    };
    let err = simplify(&tetra, &config(Target::Vertices(3), 0.001)).unwrap_err();
    assert!(matches!(
        err,
        SimplifyError::TargetUnreachable {
            target: 3,
            reached: 4
        }
    ));
}
