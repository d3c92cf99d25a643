//! ACAP consistency (Gao et al., "as consistent as possible"): choose, per vertex, which of the
//! equivalent rotation vectors of R_i to store so that neighbouring vectors agree.
//!
//! A rotation by θ ∈ (0, π] about the unit axis a has the rotation vectors (θ + 2πk)·a, k ∈ ℤ.
//! The principal one (k = 0, |ω| ≤ π) jumps where rotations pass π (θa → −θ'a'), so features
//! would not vary smoothly there. Gao et al. choose in two steps, first the axis orientation
//! (a or −a), then the angle offset (+2πt) along the oriented axis, because their angle step
//! compares scalar angles. Both choices are the one integer k here (k < 0 is the flipped axis:
//! (θ + 2πk)a = (2π|k| − θ)(−a)), and it is chosen by comparing the vectors themselves, so the
//! orientation needs no separate pass. The objective is Gao's, Σ_edges ‖ω_i − ω_j‖²:
//!
//! 1. **Propagation**: per connected component, start at the smallest (non-identity) rotation,
//!    which keeps its principal vector (so the least rotated part of the mesh has the smallest
//!    vectors; this fixes the free global multiple of 2π), and visit the mesh breadth-first; each
//!    vertex takes the k whose vector is closest to the mean μ of its already placed neighbours,
//!    in closed form k = round((a·μ − θ)/2π).
//! 2. **Refinement**: vertex by vertex (a worklist of the neighbours of every change), the same
//!    closed form against all neighbours, accepting strict decreases of the local energy only,
//!    until nothing changes (each accepted change lowers the bounded objective, so this ends).
//!
//! Rotations below [`IDENTITY_ANGLE`] (below f32 feature precision) have no meaningful axis: their
//! vector is 2πk·μ̂, the multiple of 2π closest to μ (0 unless the neighbours are near a full
//! turn). When the principal vectors already differ by less than π/2 across every edge, every
//! other choice would add a jump of more than 3π/2, so the field is kept as it is.
//!
//! Every stored vector is a valid rotation vector of the same R_i (identity-like rotations up to
//! [`IDENTITY_ANGLE`]), so reconstruction is unaffected; only smoothness improves.
//!
//! Known limit: where a rotation field passes *near but not through* the identity at a full turn
//! (e.g. a twisted tube, whose twist also shears the surface and so tilts every rotation about
//! the radial direction, at 2π of twist), the axis swings by π within a short distance and vectors
//! of length ≈ 2π must swing with it: no choice of representatives is smooth there unless the
//! mesh resolves the swing. On data that turns by less than π (horse, samba) this never arises.

use crate::rest::RestMesh;
use crate::rotation::{Vec3, add, dot, norm, scale, sub};
use std::collections::VecDeque;

/// Rotations by less than this (radians) count as the identity: any axis will do.
pub const IDENTITY_ANGLE: f64 = 1e-7;
/// Changes beyond this many per vertex stop the refinement (never reached in practice: every
/// accepted change lowers a bounded energy).
const MAX_UPDATES_PER_VERTEX: usize = 100;

/// Replaces principal rotation vectors (|ω| ≤ π) by consistent representatives, in place.
pub fn make_consistent(rest: &RestMesh, omega: &mut [Vec3]) {
    if max_neighbour_jump(rest, omega) < 0.5 * std::f64::consts::PI {
        return;
    }
    let theta: Vec<f64> = omega.iter().map(|&w| norm(w)).collect();
    let axis: Vec<Vec3> = omega
        .iter()
        .zip(&theta)
        .map(|(&w, &t)| {
            if t > IDENTITY_ANGLE {
                scale(w, 1.0 / t)
            } else {
                [0.0; 3]
            }
        })
        .collect();
    let mut b = axis;
    let psi = unwrap_angles(rest, &theta, &mut b, &theta);
    for (w, (bi, p)) in omega.iter_mut().zip(b.iter().zip(&psi)) {
        *w = scale(*bi, *p);
    }
}

/// The best vertex of each connected component by `better(i, j)` (i is better than j).
fn component_roots(rest: &RestMesh, better: impl Fn(usize, usize) -> bool) -> Vec<usize> {
    let mut roots = vec![usize::MAX; rest.component_count()];
    for (i, &c) in rest.component().iter().enumerate() {
        let r = &mut roots[c as usize];
        if *r == usize::MAX || better(i, *r) {
            *r = i;
        }
    }
    roots
}

/// Runs `update` on every vertex, then again on the neighbours of every vertex it changed,
/// until no update changes anything (or the update budget is spent).
fn refine(rest: &RestMesh, mut update: impl FnMut(usize) -> bool) {
    let n = rest.vertex_count();
    let mut queued = vec![true; n];
    let mut work: VecDeque<usize> = (0..n).collect();
    let mut budget = MAX_UPDATES_PER_VERTEX * n;
    while let Some(i) = work.pop_front() {
        queued[i] = false;
        if update(i) {
            if budget == 0 {
                break;
            }
            budget -= 1;
            for &j in rest.ring(i).0 {
                if !queued[j as usize] {
                    queued[j as usize] = true;
                    work.push_back(j as usize);
                }
            }
        }
    }
}

/// The offsets k (and the axes of identity-like rotations), by propagation then refinement.
fn unwrap_angles(rest: &RestMesh, theta: &[f64], b: &mut [Vec3], base: &[f64]) -> Vec<f64> {
    let n = theta.len();
    let two_pi = 2.0 * std::f64::consts::PI;
    let free: Vec<bool> = theta.iter().map(|&t| t <= IDENTITY_ANGLE).collect();
    let mut psi = base.to_vec();
    // The representative of vertex i closest to `target`: for a proper rotation the lattice
    // point of ψ along b_i nearest to b_i·target; for an identity-like one 2πk·target/|target|.
    let choose = |i: usize, target: Vec3, b: &[Vec3]| -> (Vec3, f64) {
        if free[i] {
            let len = norm(target);
            let k = (len / two_pi).round();
            if k == 0.0 {
                (b[i], 0.0)
            } else {
                (scale(target, 1.0 / len), two_pi * k)
            }
        } else {
            let s = dot(b[i], target);
            (b[i], base[i] + two_pi * ((s - base[i]) / two_pi).round())
        }
    };
    let mean_of =
        |i: usize, b: &[Vec3], psi: &[f64], use_j: &dyn Fn(usize) -> bool| -> Option<Vec3> {
            let (sum, count) = rest
                .ring(i)
                .0
                .iter()
                .fold(([0.0; 3], 0usize), |(s, c), &j| {
                    let j = j as usize;
                    if use_j(j) {
                        (add(s, scale(b[j], psi[j])), c + 1)
                    } else {
                        (s, c)
                    }
                });
            (count > 0).then(|| scale(sum, 1.0 / count as f64))
        };

    // Breadth-first propagation from the smallest proper rotation of each component (an exact
    // identity could equally stand for a full turn, so it is no anchor).
    let mut placed = vec![false; n];
    let mut queue = VecDeque::new();
    for root in component_roots(rest, |i, j| {
        (!free[i] && free[j]) || (free[i] == free[j] && theta[i] < theta[j])
    }) {
        placed[root] = true;
        queue.push_back(root);
        while let Some(i) = queue.pop_front() {
            for &j in rest.ring(i).0 {
                let j = j as usize;
                if placed[j] {
                    continue;
                }
                if let Some(mean) = mean_of(j, b, &psi, &|k| placed[k]) {
                    let (axis, value) = choose(j, mean, b);
                    b[j] = axis;
                    psi[j] = value;
                }
                placed[j] = true;
                queue.push_back(j);
            }
        }
    }

    // Refinement of Σ ‖ψ_i b_i − ψ_j b_j‖², one vertex at a time.
    let energy = |i: usize, w: Vec3, b: &[Vec3], psi: &[f64]| -> f64 {
        rest.ring(i)
            .0
            .iter()
            .map(|&j| {
                let d = sub(w, scale(b[j as usize], psi[j as usize]));
                dot(d, d)
            })
            .sum()
    };
    refine(rest, |i| {
        let Some(mean) = mean_of(i, b, &psi, &|_| true) else {
            return false;
        };
        let (axis, value) = choose(i, mean, b);
        if value == psi[i] && axis == b[i] {
            return false;
        }
        if energy(i, scale(axis, value), b, &psi) < energy(i, scale(b[i], psi[i]), b, &psi) - 1e-12
        {
            b[i] = axis;
            psi[i] = value;
            true
        } else {
            false
        }
    });
    psi
}

/// Largest |ω_i − ω_j| over the edges of the rest mesh (how smooth a rotation field is).
pub fn max_neighbour_jump(rest: &RestMesh, omega: &[Vec3]) -> f64 {
    (0..rest.vertex_count())
        .flat_map(|i| rest.ring(i).0.iter().map(move |&j| (i, j as usize)))
        .map(|(i, j)| norm(sub(omega[i], omega[j])))
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::flat_grid;
    use std::f64::consts::PI;

    /// A strip along x whose rotation about z grows from 0 to `total` along x (axes tilted by
    /// ≤ 1e-4 so that they are not all parallel; a larger tilt would make the full turn singular,
    /// see the module notes).
    fn strip_field(total: f64) -> (RestMesh, Vec<Vec3>, Vec<Vec3>) {
        let (pos, faces) = flat_grid(40, 3, 0.0);
        let rest = RestMesh::new(&pos, &faces).unwrap();
        let truth: Vec<Vec3> = rest
            .positions()
            .iter()
            .map(|p| [0.0, 1e-4 * p[1], total * p[0]])
            .collect();
        let principal: Vec<Vec3> = truth
            .iter()
            .map(|&w| crate::rotation::log_rotation(&crate::rotation::exp_rotation(w)))
            .collect();
        (rest, truth, principal)
    }

    #[test]
    fn unwraps_a_rotation_that_passes_pi_and_two_pi() {
        for total in [1.5 * PI, 2.5 * PI, 3.5 * PI] {
            let (rest, truth, mut omega) = strip_field(total);
            assert!(
                max_neighbour_jump(&rest, &omega) > PI,
                "the principal field must jump"
            );
            make_consistent(&rest, &mut omega);
            // As smooth as the true field (whose steps are ≈ total/39 plus the grid's jitter).
            let smooth = max_neighbour_jump(&rest, &truth);
            assert!(max_neighbour_jump(&rest, &omega) < smooth + 1e-6, "{total}");
            assert!(smooth < 0.45);
            // Same rotations as before, and the truth up to one global multiple of 2π along z.
            for (w, t) in omega.iter().zip(&truth) {
                let r1 = crate::rotation::exp_rotation(*w);
                let r2 = crate::rotation::exp_rotation(*t);
                for r in 0..3 {
                    assert!(norm(sub(r1[r], r2[r])) < 1e-9);
                }
            }
            let offset = omega[0][2] - truth[0][2];
            assert!(
                (offset / (2.0 * PI)).fract().abs() < 1e-9
                    || (offset / (2.0 * PI)).fract().abs() > 1.0 - 1e-9
            );
            for (w, t) in omega.iter().zip(&truth) {
                assert!((w[2] - t[2] - offset).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn smooth_principal_fields_are_left_alone() {
        let (rest, truth, mut omega) = strip_field(0.9 * PI);
        make_consistent(&rest, &mut omega);
        for (w, t) in omega.iter().zip(&truth) {
            assert!(norm(sub(*w, *t)) < 1e-9);
        }
    }

    #[test]
    fn identity_rotations_follow_a_full_turn() {
        // Rotations about z growing to 2π + 0.5 along x, exactly the identity where they pass 2π.
        let (rest, _, _) = strip_field(0.0);
        let mut omega: Vec<Vec3> = rest
            .positions()
            .iter()
            .map(|p| {
                let t = (2.0 * PI + 0.5) * p[0];
                let w = if (t - 2.0 * PI).abs() < 0.05 {
                    [0.0; 3]
                } else {
                    [0.0, 1e-4 * p[1], t]
                };
                crate::rotation::log_rotation(&crate::rotation::exp_rotation(w))
            })
            .collect();
        assert!(omega.iter().any(|w| norm(*w) == 0.0));
        make_consistent(&rest, &mut omega);
        assert!(max_neighbour_jump(&rest, &omega) < 0.3);
    }
}
