//! The editable mesh's operations: each keeps a consistently oriented 2-manifold of the same
//! Euler characteristic, and the link condition refuses what would pinch or fold.

use super::*;
use crate::geometry::to_f64;
use crate::manifold::manifold_defect;
use crate::remesh::surface::NONE;
use mesh_io::{QualityReport, TriMesh};

fn editable(mesh: &TriMesh) -> Editable {
    let topology = crate::manifold::topology(mesh.vertex_count(), &mesh.faces).unwrap();
    let mut loop_of = vec![NONE; mesh.vertex_count()];
    for &e in &topology.boundary {
        for v in topology.edges[e as usize] {
            loop_of[v as usize] = 0;
        }
    }
    let positions = mesh.positions.iter().map(|&p| to_f64(p)).collect();
    Editable::new(
        positions,
        &mesh.faces,
        loop_of,
        vec![0; mesh.vertex_count()],
    )
}

/// Manifold, same Euler characteristic, consistent orientation (every inner edge is run
/// once each way), face lists matching the faces.
fn check(m: &Editable, euler: i64) {
    let (positions, faces, _) = m.compact();
    assert_eq!(positions.len(), m.vertex_count());
    assert_eq!(manifold_defect(positions.len(), &faces), None);
    let p32: Vec<[f32; 3]> = positions.iter().map(|p| p.map(|x| x as f32)).collect();
    let q = QualityReport::of_mesh(&p32, &faces);
    assert_eq!(q.euler_characteristic, euler);
    assert_eq!(q.unused_vertices, 0);
    let mut runs: Vec<[u32; 2]> = faces
        .iter()
        .flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
        .collect();
    runs.sort_unstable();
    assert!(runs.windows(2).all(|w| w[0] != w[1]), "orientation");
    for v in 0..m.slots() as u32 {
        let listed: Vec<u32> = m.faces_around(v).to_vec();
        let mut expected: Vec<u32> = m
            .live_faces()
            .filter(|(_, f)| f.contains(&v))
            .map(|(i, _)| i)
            .collect();
        let mut sorted = listed.clone();
        sorted.sort_unstable();
        expected.sort_unstable();
        assert_eq!(sorted, expected, "faces around {v}");
    }
}

#[test]
fn split_adds_one_vertex_and_keeps_the_surface() {
    for mesh in [crate::shapes::icosphere(1), crate::shapes::bumpy_grid(4, 4)] {
        let euler = QualityReport::of_mesh(&mesh.positions, &mesh.faces).euler_characteristic;
        let mut m = editable(&mesh);
        let faces = m.live_faces().count();
        for [a, b] in m.edges().into_iter().step_by(3) {
            let boundary = m.edge_faces(a, b).count == 1;
            let v = m.split(a, b, m.midpoint(a, b));
            assert_eq!(m.is_boundary(v), boundary);
            assert_eq!(m.valence(v), if boundary { 3 } else { 4 });
            check(&m, euler);
        }
        assert!(m.live_faces().count() > faces);
    }
}

#[test]
fn unsplit_restores_the_mesh_exactly() {
    for mesh in [crate::shapes::icosphere(1), crate::shapes::bumpy_grid(4, 4)] {
        let mut m = editable(&mesh);
        let faces: Vec<(u32, [u32; 3])> = m.live_faces().collect();
        for [a, b] in m.edges() {
            let around: Vec<Vec<u32>> = (0..m.slots() as u32)
                .map(|v| {
                    let mut l = m.faces_around(v).to_vec();
                    l.sort_unstable();
                    l
                })
                .collect();
            m.split(a, b, m.midpoint(a, b));
            m.unsplit_last();
            assert_eq!(m.live_faces().collect::<Vec<_>>(), faces);
            assert_eq!(m.slots(), mesh.vertex_count());
            assert_eq!(m.vertex_count(), mesh.vertex_count());
            for (v, list) in around.iter().enumerate() {
                let mut now = m.faces_around(v as u32).to_vec();
                now.sort_unstable();
                assert_eq!(&now, list);
            }
        }
    }
}

#[test]
fn flip_turns_the_diagonal_and_keeps_the_surface() {
    let mesh = crate::shapes::icosphere(1);
    let mut m = editable(&mesh);
    let [a, b] = m.edges()[0];
    let [c, d] = m.can_flip(a, b).expect("flippable");
    let valences = [a, b, c, d].map(|v| m.valence(v));
    m.flip(a, b);
    assert_eq!(m.edge_faces(a, b).count, 0);
    assert_eq!(m.edge_faces(c, d).count, 2);
    assert_eq!(
        [a, b, c, d].map(|v| m.valence(v)),
        [
            valences[0] - 1,
            valences[1] - 1,
            valences[2] + 1,
            valences[3] + 1
        ]
    );
    check(&m, 2);
    // (a, b) are unjoined again: the flip can be undone.
    assert_eq!(
        m.can_flip(c, d).map(|mut x| {
            x.sort();
            x
        }),
        Some([a.min(b), a.max(b)])
    );
    // A boundary edge never flips.
    let grid = editable(&crate::shapes::bumpy_grid(3, 3));
    assert_eq!(grid.can_flip(0, 1), None);
}

#[test]
fn collapses_keep_a_manifold_until_the_link_condition_refuses() {
    // Collapse everything collapsible, lowest edges first: each step stays a manifold of
    // the same Euler characteristic, and the end is tiny (a tetrahedron, a triangle strip).
    for (mesh, floor) in [
        (crate::shapes::icosphere(2), 4),
        (crate::shapes::torus(8, 6, 1.0, 0.3), 7),
        (crate::shapes::bumpy_grid(5, 4), 3),
    ] {
        let euler = QualityReport::of_mesh(&mesh.positions, &mesh.faces).euler_characteristic;
        let mut m = editable(&mesh);
        let mut scratch = Scratch::default();
        loop {
            let mut progress = false;
            for [a, b] in m.edges() {
                if !m.is_alive(a) || !m.is_alive(b) {
                    continue;
                }
                // Keep the boundary vertex, as the remesher does.
                let (a, b) = if m.is_boundary(a) { (b, a) } else { (a, b) };
                if m.is_boundary(a) && m.edge_faces(a, b).count != 1 {
                    continue;
                }
                if m.can_collapse(a, b, &mut scratch) {
                    let p = m.midpoint(a, b);
                    m.collapse(a, b, p);
                    check(&m, euler);
                    progress = true;
                }
            }
            if !progress {
                break;
            }
        }
        assert!(
            m.vertex_count() <= floor,
            "{} of {} left",
            m.vertex_count(),
            mesh.vertex_count()
        );
    }
}

#[test]
fn link_condition_refuses_a_pinch_and_the_tetrahedron() {
    // An octahedron; collapses take it to a triangular bipyramid, then a tetrahedron.
    let octahedron = TriMesh {
        positions: vec![
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ],
        faces: vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ],
    };
    let mut m = editable(&octahedron);
    let mut s = Scratch::default();
    // 0 and 1 are opposite: not an edge.
    assert!(!m.can_collapse(0, 1, &mut s));
    // (0, 2) has common neighbours 4 and 5, exactly its opposite corners.
    assert!(m.can_collapse(0, 2, &mut s));
    m.collapse(0, 2, m.midpoint(0, 2));
    check(&m, 2);
    // The bipyramid: equator 1-2-3, poles 4 and 5. The equator edge (1, 2) has opposite
    // corners 4 and 5 but also the common neighbour 3: collapsing would pinch.
    assert!(!m.can_collapse(1, 2, &mut s));
    assert!(!m.can_collapse(2, 1, &mut s));
    // A pole edge is fine and leaves a tetrahedron, where every collapse is refused.
    assert!(m.can_collapse(2, 4, &mut s));
    m.collapse(2, 4, m.midpoint(2, 4));
    check(&m, 2);
    assert_eq!(m.vertex_count(), 4);
    for [a, b] in m.edges() {
        assert!(!m.can_collapse(a, b, &mut s) && !m.can_collapse(b, a, &mut s));
    }
}
