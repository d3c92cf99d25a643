//! Isotropic remeshing: the real templates (skipped when the data sets are absent) and meshes
//! generated in code — exact counts, topology kept, no flipped or degenerate faces, vertices on
//! the template, more even edges than QEM, a partition into connected non-empty clusters,
//! determinism, and typed errors on bad input.

use mesh_io::{QualityReport, TriMesh};
use qem_simplify::manifold::manifold_defect;
use qem_simplify::shapes::{bumpy_grid, icosphere, torus};
use qem_simplify::{
    RemeshConfig, Remeshed, SimplifyConfig, SimplifyError, SimplifyReport, Smoothing, Target,
    edge_length_cv, flipped_faces_on_surface, remesh, simplify,
};
use std::collections::VecDeque;
use std::time::Instant;

fn config(target: Target) -> RemeshConfig {
    RemeshConfig {
        target,
        ..RemeshConfig::default()
    }
}

/// Asserts what every remeshing of `fine` to `target` vertices must satisfy.
fn check_remeshed(fine: &TriMesh, r: &Remeshed, target: usize) {
    let coarse = &r.coarse;
    assert_eq!(coarse.vertex_count(), target, "exact target count");
    assert_eq!(manifold_defect(target, &coarse.faces), None, "manifold");
    let q_in = QualityReport::of_mesh(&fine.positions, &fine.faces);
    let q_out = QualityReport::of_mesh(&coarse.positions, &coarse.faces);
    // Vertices no face uses are left out of the remeshing (they count in V − E + F).
    assert_eq!(
        q_in.euler_characteristic - q_in.unused_vertices as i64,
        q_out.euler_characteristic,
        "Euler"
    );
    assert_eq!(q_in.components, q_out.components, "components kept");
    assert_eq!(
        q_in.boundary_edges > 0,
        q_out.boundary_edges > 0,
        "boundary kept"
    );
    assert_eq!(q_out.unused_vertices, 0);
    assert_eq!(q_out.degenerate_faces, 0, "no degenerate faces");
    assert_eq!(
        flipped_faces_on_surface(fine, coarse),
        0,
        "no flipped faces"
    );
    // A partition of the fine vertices into non-empty, connected clusters.
    assert_eq!(r.cluster_of.len(), fine.vertex_count());
    assert!(r.cluster_of.iter().all(|&c| (c as usize) < target));
    let sizes = r.cluster_sizes();
    assert_eq!(sizes.iter().sum::<usize>(), fine.vertex_count());
    assert!(sizes.iter().all(|&s| s > 0), "an empty cluster");
    assert_clusters_connected(fine, &r.cluster_of, target);
}

/// Each cluster's fine vertices that faces use are one connected piece of the fine mesh.
fn assert_clusters_connected(fine: &TriMesh, cluster_of: &[u32], clusters: usize) {
    let n = fine.vertex_count();
    let mut adjacency = vec![Vec::new(); n];
    for f in &fine.faces {
        for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
            adjacency[a as usize].push(b);
            adjacency[b as usize].push(a);
        }
    }
    let mut pieces = vec![0; clusters];
    let mut seen = vec![false; n];
    for start in 0..n {
        if seen[start] || adjacency[start].is_empty() {
            continue;
        }
        let c = cluster_of[start];
        pieces[c as usize] += 1;
        seen[start] = true;
        let mut queue = VecDeque::from([start]);
        while let Some(v) = queue.pop_front() {
            for &w in &adjacency[v] {
                if !seen[w as usize] && cluster_of[w as usize] == c {
                    seen[w as usize] = true;
                    queue.push_back(w as usize);
                }
            }
        }
    }
    assert!(
        pieces.iter().all(|&p| p <= 1),
        "a cluster in several pieces"
    );
}

/// Largest distance from the coarse vertices to the template's surface (brute force).
fn distance_to_template(fine: &TriMesh, coarse: &TriMesh) -> f64 {
    let mut worst = 0.0f64;
    for p in &coarse.positions {
        let p = p.map(f64::from);
        let best = fine
            .faces
            .iter()
            .map(|f| {
                point_triangle_distance(p, f.map(|v| fine.positions[v as usize].map(f64::from)))
            })
            .fold(f64::INFINITY, f64::min);
        worst = worst.max(best);
    }
    worst
}

/// Reference point–triangle distance: the projection onto the plane if it falls inside,
/// else the nearest of the three sides.
fn point_triangle_distance(p: [f64; 3], [a, b, c]: [[f64; 3]; 3]) -> f64 {
    let sub = |x: [f64; 3], y: [f64; 3]| [x[0] - y[0], x[1] - y[1], x[2] - y[2]];
    let dot = |x: [f64; 3], y: [f64; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
    let cross = |x: [f64; 3], y: [f64; 3]| {
        [
            x[1] * y[2] - x[2] * y[1],
            x[2] * y[0] - x[0] * y[2],
            x[0] * y[1] - x[1] * y[0],
        ]
    };
    let segment = |a: [f64; 3], b: [f64; 3]| {
        let ab = sub(b, a);
        let t = (dot(sub(p, a), ab) / dot(ab, ab).max(1e-300)).clamp(0.0, 1.0);
        let q = [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]];
        dot(sub(p, q), sub(p, q)).sqrt()
    };
    let n = cross(sub(b, a), sub(c, a));
    let nn = dot(n, n);
    if nn > 0.0 {
        let inside = [(a, b), (b, c), (c, a)]
            .iter()
            .all(|&(x, y)| dot(cross(sub(y, x), sub(p, x)), n) >= 0.0);
        if inside {
            return dot(sub(p, a), n).abs() / nn.sqrt();
        }
    }
    segment(a, b).min(segment(b, c)).min(segment(c, a))
}

#[test]
fn sphere_torus_and_open_grid_at_half() {
    let meshes = [
        ("icosphere", icosphere(3)),
        ("torus", torus(40, 16, 1.0, 0.35)),
        ("grid", bumpy_grid(30, 24)),
    ];
    for (name, mesh) in meshes {
        let target = mesh.vertex_count().div_ceil(2);
        let r = remesh(&mesh, &RemeshConfig::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        check_remeshed(&mesh, &r, target);
        // Every coarse vertex on the original surface (projection), edges more even than the
        // input's and than classical QEM's at the same count.
        let off = distance_to_template(&mesh, &r.coarse);
        assert!(off < 1e-6 * mesh.bbox_diagonal(), "{name}: {off}");
        let cv = edge_length_cv(&r.coarse.positions, &r.coarse.faces);
        let qem = simplify(&mesh, &SimplifyConfig::default()).unwrap().coarse;
        let cv_qem = edge_length_cv(&qem.positions, &qem.faces);
        assert!(cv < cv_qem, "{name}: remesh {cv} vs QEM {cv_qem}");
    }
}

#[test]
fn boundary_vertices_stay_on_the_boundary() {
    let grid = bumpy_grid(30, 24);
    let r = remesh(&grid, &RemeshConfig::default()).unwrap();
    // The boundary edges of the coarse mesh have their ends on the square's sides.
    let mut sides: Vec<[u32; 2]> = r
        .coarse
        .faces
        .iter()
        .flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
        .map(|[a, b]| [a.min(b), a.max(b)])
        .collect();
    sides.sort_unstable();
    let boundary: Vec<u32> = sides
        .chunk_by(|x, y| x == y)
        .filter(|run| run.len() == 1)
        .flat_map(|run| run[0])
        .collect();
    assert!(boundary.len() > 20);
    for v in boundary {
        let [x, y, _] = r.coarse.positions[v as usize];
        let on_side = [x, y]
            .iter()
            .any(|&c| c.abs() < 1e-5 || (c - 1.0).abs() < 1e-5);
        assert!(on_side, "boundary vertex {v} at ({x}, {y})");
    }
}

#[test]
fn uneven_sampling_becomes_even() {
    // A sphere sampled densely near one pole: the remesh's edges are far more even than both
    // the input's and QEM's (λ = 0.001 and λ = 0).
    let mut mesh = icosphere(4);
    for p in &mut mesh.positions {
        let t = 0.5 * (1.0 + p[2]);
        let q = [
            p[0] * (1.0 - 0.6 * t),
            p[1] * (1.0 - 0.6 * t),
            p[2] + 0.6 * t,
        ];
        let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
        *p = q.map(|x| x / n);
    }
    let r = remesh(&mesh, &RemeshConfig::default()).unwrap();
    check_remeshed(&mesh, &r, mesh.vertex_count().div_ceil(2));
    let cv = edge_length_cv(&r.coarse.positions, &r.coarse.faces);
    assert!(cv < 0.5 * edge_length_cv(&mesh.positions, &mesh.faces));
    for lambda in [0.0, 0.001] {
        let s = simplify(
            &mesh,
            &SimplifyConfig {
                target: Target::Ratio(0.5),
                lambda,
            },
        )
        .unwrap();
        assert!(cv < edge_length_cv(&s.coarse.positions, &s.coarse.faces));
    }
    // Uniform weights work too, a little less evenly.
    let uniform = RemeshConfig {
        smoothing: Smoothing::Uniform,
        ..RemeshConfig::default()
    };
    let u = remesh(&mesh, &uniform).unwrap();
    check_remeshed(&mesh, &u, mesh.vertex_count().div_ceil(2));
}

#[test]
fn exact_counts_down_and_up() {
    let sphere = icosphere(3); // 642 vertices
    for target in [40, 200, 321, 600, 642] {
        let r = remesh(&sphere, &config(Target::Vertices(target)))
            .unwrap_or_else(|e| panic!("{target}: {e}"));
        check_remeshed(&sphere, &r, target);
    }
    let torus = torus(30, 12, 1.0, 0.4); // 360 vertices, genus 1
    let r = remesh(&torus, &config(Target::Ratio(0.25))).unwrap();
    check_remeshed(&torus, &r, 90);
}

#[test]
fn several_components_and_unused_vertices_make_one_partition() {
    // A big sphere, a small torus beside it, and two vertices no face uses.
    let sphere = icosphere(3);
    let ring = torus(24, 8, 0.5, 0.15);
    let mut positions = sphere.positions.clone();
    let shift = positions.len() as u32;
    positions.extend(ring.positions.iter().map(|p| [p[0] + 3.0, p[1], p[2]]));
    let mut faces = sphere.faces.clone();
    faces.extend(ring.faces.iter().map(|f| f.map(|v| v + shift)));
    positions.extend([[0.0, 0.0, 5.0], [3.0, 0.0, -4.0]]);
    let mesh = TriMesh { positions, faces };
    let target = mesh.vertex_count().div_ceil(2);
    let r = remesh(&mesh, &RemeshConfig::default()).unwrap();
    check_remeshed(&mesh, &r, target);
    // Each fine component maps onto coarse vertices of the same component (near it).
    let n = mesh.vertex_count();
    for v in 0..n - 2 {
        let c = r.coarse.positions[r.cluster_of[v] as usize];
        let own_side = if (v as u32) < shift {
            c[0] < 1.5
        } else {
            c[0] > 1.5
        };
        assert!(
            own_side,
            "fine vertex {v} in a cluster of the other component"
        );
    }
    // The lone vertices join their nearest coarse vertex: the top of the sphere, the torus.
    assert!(r.coarse.positions[r.cluster_of[n - 2] as usize][2] > 0.9);
    assert!(r.coarse.positions[r.cluster_of[n - 1] as usize][0] > 1.5);
}

#[test]
fn same_input_same_output_on_any_thread_count() {
    let mesh = torus(36, 14, 1.0, 0.3);
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool")
            .install(|| remesh(&mesh, &RemeshConfig::default()))
            .expect("remeshes")
    };
    let one = run(1);
    assert_eq!(one, run(3));
    assert_eq!(one, run(1));
}

#[test]
fn bad_input_gives_typed_errors() {
    let sphere = icosphere(1);
    let n = sphere.vertex_count();
    for target in [
        Target::Vertices(0),
        Target::Vertices(n + 1),
        Target::Ratio(0.0),
    ] {
        let err = remesh(&sphere, &config(target)).unwrap_err();
        assert!(
            matches!(err, SimplifyError::InvalidArgument { .. }),
            "{target:?}: {err}"
        );
    }
    let no_rounds = RemeshConfig {
        iterations: 0,
        ..RemeshConfig::default()
    };
    assert!(matches!(
        remesh(&sphere, &no_rounds),
        Err(SimplifyError::InvalidArgument {
            argument: "iterations",
            ..
        })
    ));
    let mut nan = sphere.clone();
    nan.positions[3][1] = f32::NAN;
    assert!(matches!(
        remesh(&nan, &RemeshConfig::default()),
        Err(SimplifyError::MeshIo(mesh_io::MeshIoError::NonFinite {
            vertex: 3,
            ..
        }))
    ));
    // Two triangles sharing only a vertex.
    let bow_tie = TriMesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
        ],
        faces: vec![[0, 1, 2], [0, 3, 4]],
    };
    assert!(matches!(
        remesh(&bow_tie, &RemeshConfig::default()),
        Err(SimplifyError::NonManifold(_))
    ));
    let mut out_of_range = sphere.clone();
    out_of_range.faces[0][0] = n as u32;
    assert!(matches!(
        remesh(&out_of_range, &RemeshConfig::default()),
        Err(SimplifyError::MeshIo(_))
    ));
    let collinear = TriMesh {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
        faces: vec![[0, 1, 2]],
    };
    assert!(matches!(
        remesh(&collinear, &RemeshConfig::default()),
        Err(SimplifyError::ZeroArea { faces: 1 })
    ));
    let point = TriMesh {
        positions: vec![[1.0; 3]; 3],
        faces: vec![[0, 1, 2]],
    };
    assert!(matches!(
        remesh(&point, &RemeshConfig::default()),
        Err(SimplifyError::ZeroExtent { vertices: 3 })
    ));
    // A tetrahedron cannot lose a vertex and stay a closed surface.
    let tetra = TriMesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        faces: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]],
    };
    assert!(matches!(
        remesh(&tetra, &config(Target::Vertices(3))),
        Err(SimplifyError::TargetUnreachable { target: 3, .. })
    ));
}

/// The real templates: the acceptance properties, and edges more even than QEM's with λ =
/// 0.001 and with λ = 0 on the same template. Prints one markdown row per method (the figures
/// of docs/benchmarks.md, "Isotropic remeshing").
fn acceptance(name: &str) {
    let Some(dir) = mesh_io::datasets::find_or_skip(name) else {
        return;
    };
    let fine = mesh_io::load_set(&dir)
        .expect("data set loads")
        .value
        .template();
    let target = fine.vertex_count().div_ceil(2);
    let start = Instant::now();
    let r = remesh(&fine, &RemeshConfig::default()).expect("remeshes");
    let seconds = start.elapsed().as_secs_f64();
    check_remeshed(&fine, &r, target);
    let row = |method: &str, report: &SimplifyReport| {
        eprintln!(
            "| {name} | {method} | {:.4} | {:.2e} | {:.3} | {:.3} | {} | {:.2} |",
            report.edge_cv,
            report.geometric_error_rel,
            report.cluster_cv,
            report.cluster_area_cv,
            report.flipped_faces,
            report.seconds
        )
    };
    let report = SimplifyReport::of_remeshed(&fine, &r, seconds);
    row("remesh", &report);
    for lambda in [0.001, 0.0] {
        let start = Instant::now();
        let s = simplify(
            &fine,
            &SimplifyConfig {
                target: Target::Ratio(0.5),
                lambda,
            },
        )
        .expect("simplifies");
        let qem = SimplifyReport::of(&fine, &s, lambda, start.elapsed().as_secs_f64());
        row(&format!("QEM λ={lambda}"), &qem);
        assert!(
            report.edge_cv < qem.edge_cv,
            "{name}: remesh {} vs QEM lambda={lambda} {}",
            report.edge_cv,
            qem.edge_cv
        );
    }
}

#[test]
fn horse_gallop_template() {
    acceptance("horse-gallop");
}

#[test]
fn samba_template() {
    acceptance("samba");
}

#[test]
fn elephant_gallop_template() {
    acceptance("elephant-gallop");
}
