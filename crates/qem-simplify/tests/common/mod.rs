//! Checks every simplification result must pass, shared by the test files.

use mesh_io::{QualityReport, TriMesh};
use qem_simplify::{Simplified, flipped_faces, manifold::manifold_defect};
use std::collections::VecDeque;

/// Asserts the acceptance properties of `s`, the simplification of `fine` to `target` vertices.
pub fn check_simplified(fine: &TriMesh, s: &Simplified, target: usize) {
    let coarse = &s.coarse;
    assert_eq!(coarse.vertex_count(), target, "exact target count");
    assert_eq!(s.survivors.len(), target);
    assert!(
        s.survivors.windows(2).all(|w| w[0] < w[1]),
        "survivors ascending"
    );
    assert_eq!(
        manifold_defect(target, &coarse.faces),
        None,
        "manifold output"
    );
    let q_in = QualityReport::of_mesh(&fine.positions, &fine.faces);
    let q_out = QualityReport::of_mesh(&coarse.positions, &coarse.faces);
    assert_eq!(
        q_in.euler_characteristic, q_out.euler_characteristic,
        "Euler characteristic"
    );
    assert_eq!(
        q_in.boundary_edges > 0,
        q_out.boundary_edges > 0,
        "boundary kept"
    );
    assert_eq!(q_in.components, q_out.components, "components kept");
    assert_eq!(q_out.degenerate_faces, 0, "no degenerate faces");
    assert_eq!(flipped_faces(fine, s), 0, "no flipped faces");
    assert_eq!(s.face_origin.len(), coarse.face_count());
    assert!(s.face_origin.windows(2).all(|w| w[0] < w[1]));
    // Each coarse face is its fine face relabelled by the cluster map.
    for (face, &origin) in coarse.faces.iter().zip(&s.face_origin) {
        let relabelled = fine.faces[origin as usize].map(|v| s.cluster_of[v as usize]);
        assert_eq!(*face, relabelled);
    }
    // Every fine vertex mapped exactly once; each survivor in its own cluster.
    assert_eq!(s.cluster_of.len(), fine.vertex_count());
    assert!(s.cluster_of.iter().all(|&c| (c as usize) < target));
    for (k, &v) in s.survivors.iter().enumerate() {
        assert_eq!(
            s.cluster_of[v as usize], k as u32,
            "survivor {v} maps to its coarse vertex"
        );
    }
    let clusters = s.clusters();
    assert_eq!(
        clusters.iter().map(Vec::len).sum::<usize>(),
        fine.vertex_count()
    );
    assert!(clusters.iter().all(|c| !c.is_empty()));
    assert_clusters_connected(fine, s);
}

/// Breadth-first search inside each cluster over the fine mesh's edges reaches all of it.
pub fn assert_clusters_connected(fine: &TriMesh, s: &Simplified) {
    let n = fine.vertex_count();
    let mut adjacency = vec![Vec::new(); n];
    for f in &fine.faces {
        for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
            adjacency[a as usize].push(b);
            adjacency[b as usize].push(a);
        }
    }
    let mut reached = vec![false; n];
    for &root in &s.survivors {
        let cluster = s.cluster_of[root as usize];
        let mut queue = VecDeque::from([root]);
        reached[root as usize] = true;
        while let Some(v) = queue.pop_front() {
            for &w in &adjacency[v as usize] {
                if !reached[w as usize] && s.cluster_of[w as usize] == cluster {
                    reached[w as usize] = true;
                    queue.push_back(w);
                }
            }
        }
    }
    let stray = reached.iter().position(|r| !r);
    assert_eq!(
        stray, None,
        "a fine vertex not connected to its cluster's survivor"
    );
}
