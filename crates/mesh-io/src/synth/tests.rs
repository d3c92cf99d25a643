//! Tests of the synthetic capsule set: measured from the generated positions.

use super::*;
use crate::QualityReport;

fn small() -> SynthConfig {
    SynthConfig {
        meshes_per_label: 6,
        ..SynthConfig::default()
    }
}

fn f64p(p: Point) -> [f64; 3] {
    p.map(f64::from)
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Signed volume enclosed by the triangles (positive when they face outward).
fn signed_volume(positions: &[Point], faces: &[Face]) -> f64 {
    faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| f64p(positions[i as usize]));
            dot(a, cross(b, c)) / 6.0
        })
        .sum()
}

/// Wraps an angle into (−π, π].
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI { w - TAU } else { w }
}

/// Number of rings between the poles.
fn ring_count(config: &SynthConfig) -> usize {
    config.rings + 2 * config.cap_rings
}

/// Vertex indices of ring `k` (0 = the bottom cap's ring next to the pole).
fn ring(config: &SynthConfig, k: usize) -> std::ops::Range<usize> {
    1 + k * config.segments..1 + (k + 1) * config.segments
}

/// The rotation about z of every ring relative to `rest`, unwrapped along the axis (so turns
/// beyond ±π add up), after checking that each ring turned rigidly.
fn ring_rotations(rest: &[Point], frame: &[Point], config: &SynthConfig) -> Vec<f64> {
    let mut rotations: Vec<f64> = Vec::new();
    for k in 0..ring_count(config) {
        let turns: Vec<f64> = ring(config, k)
            .map(|i| {
                let (r, p) = (rest[i], frame[i]);
                wrap((p[1] as f64).atan2(p[0] as f64) - (r[1] as f64).atan2(r[0] as f64))
            })
            .collect();
        for t in &turns {
            assert!(
                wrap(t - turns[0]).abs() < 1e-4,
                "ring {k} did not turn rigidly"
            );
        }
        let turn = turns[0];
        rotations.push(match rotations.last() {
            Some(&previous) => previous + wrap(turn - previous),
            None => turn,
        });
    }
    rotations
}

/// The axis as a polyline: bottom pole, ring centroids, top pole.
fn axis_polyline(frame: &[Point], config: &SynthConfig) -> Vec<[f64; 3]> {
    let mut points = vec![f64p(frame[0])];
    for k in 0..ring_count(config) {
        let mut c = [0.0; 3];
        for i in ring(config, k) {
            for (ck, pk) in c.iter_mut().zip(f64p(frame[i])) {
                *ck += pk / config.segments as f64;
            }
        }
        points.push(c);
    }
    points.push(f64p(frame[frame.len() - 1]));
    points
}

fn polyline_length(points: &[[f64; 3]]) -> f64 {
    points.windows(2).map(|w| norm(sub(w[1], w[0]))).sum()
}

/// Ratio of every edge's length in `frame` to its length in `rest`: (min, max).
fn edge_ratio_range(rest: &[Point], frame: &[Point], faces: &[Face]) -> (f64, f64) {
    let mut range = (f64::INFINITY, 0f64);
    for f in faces {
        for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
            let (a, b) = (a as usize, b as usize);
            let ratio =
                norm(sub(f64p(frame[a]), f64p(frame[b]))) / norm(sub(f64p(rest[a]), f64p(rest[b])));
            range = (range.0.min(ratio), range.1.max(ratio));
        }
    }
    range
}

fn assert_closed_genus0(positions: &[Point], faces: &[Face], what: &str) {
    let q = QualityReport::of_mesh(positions, faces);
    assert_eq!(q.boundary_edges, 0, "{what}");
    assert_eq!(q.nonmanifold_edges, 0, "{what}");
    assert_eq!(q.degenerate_faces, 0, "{what}");
    assert_eq!(q.components, 1, "{what}");
    assert_eq!(q.unused_vertices, 0, "{what}");
    assert_eq!(q.euler_characteristic, 2, "{what}");
}

#[test]
fn rest_capsule_is_a_closed_outward_genus0_surface() {
    let config = SynthConfig::default();
    let rest = rest_capsule(&config);
    assert_eq!(rest.vertex_count(), 2498);
    assert_eq!(rest.vertex_count(), config.vertex_count());
    assert_closed_genus0(&rest.positions, &rest.faces, "rest");
    assert!(signed_volume(&rest.positions, &rest.faces) > 0.0);

    // Every face points away from the axis point nearest to it (caps: the cap's centre).
    let half = config.length as f64 / 2.0;
    for (i, f) in rest.faces.iter().enumerate() {
        let [a, b, c] = f.map(|i| f64p(rest.positions[i as usize]));
        let normal = cross(sub(b, a), sub(c, a));
        let centroid = [0, 1, 2].map(|k| (a[k] + b[k] + c[k]) / 3.0);
        let axis_point = [0.0, 0.0, centroid[2].clamp(-half, half)];
        assert!(
            dot(normal, sub(centroid, axis_point)) > 0.0,
            "face {i} faces inward"
        );
    }
}

#[test]
fn rest_volume_matches_the_analytic_one() {
    // Few segments would under-fill the section; use a fine mesh and compare with the integral:
    // area of the section = πr²(1 + (c2² + c3²)/2), cylinder a frustum, caps half-ellipsoids.
    let config = SynthConfig {
        rings: 200,
        segments: 400,
        cap_rings: 100,
        ..SynthConfig::default()
    };
    let rest = rest_capsule(&config);
    let (rb, rt, l) = (0.55, 0.45, 4.0);
    let shape = PI * (1.0 + (CROSS_COS2.powi(2) + CROSS_COS3.powi(2)) / 2.0);
    let frustum = shape * l * (rb * rb + rb * rt + rt * rt) / 3.0;
    let caps = shape * 2.0 / 3.0 * (rb.powi(3) + rt.powi(3));
    let volume = signed_volume(&rest.positions, &rest.faces);
    let expected = frustum + caps;
    assert!(
        ((volume - expected) / expected).abs() < 2e-3,
        "{volume} vs {expected}"
    );
}

#[test]
fn rest_capsule_has_no_rotational_symmetry() {
    let config = SynthConfig::default();
    let rest = rest_capsule(&config);
    let mid = ring(&config, ring_count(&config) / 2);
    let radii: Vec<f64> = rest.positions[mid]
        .iter()
        .map(|p| (p[0] as f64).hypot(p[1] as f64))
        .collect();
    let n = radii.len();
    for shift in 1..n {
        let difference = (0..n)
            .map(|m| (radii[m] - radii[(m + shift) % n]).abs())
            .fold(0.0, f64::max);
        assert!(difference > 0.01, "symmetric under a turn of {shift}/{n}");
    }
    // Nor is it symmetric end to end: the caps differ.
    let (lo, hi) = rest.bbox().unwrap();
    assert!((lo[2] + hi[2]).abs() > 0.05);
}

#[test]
fn generate_is_deterministic_by_seed() {
    let config = small();
    let a = generate(&config).unwrap();
    let b = generate(&config).unwrap();
    assert_eq!(a, b);
    let bits = |s: &SynthSet| {
        s.set
            .positions()
            .iter()
            .flatten()
            .map(|c| c.to_bits())
            .collect()
    };
    let bits_a: Vec<u32> = bits(&a);
    assert_eq!(bits_a, bits(&b));
    let c = generate(&SynthConfig { seed: 7, ..config }).unwrap();
    assert_ne!(a.params, c.params);
    assert_ne!(a.set.positions(), c.set.positions());
}

#[test]
fn every_frame_stays_closed_genus0_and_outward() {
    let config = small();
    let data = generate(&config).unwrap();
    let faces = data.set.faces();
    let rest_volume = signed_volume(data.set.frame(0), faces);
    for (i, frame) in data.set.frames().enumerate() {
        assert_closed_genus0(frame, faces, &format!("frame {i}"));
        let volume = signed_volume(frame, faces);
        // Twists and bends preserve volume in the continuum; the mesh stays within a few %.
        assert!(
            (volume / rest_volume - 1.0).abs() < 0.05,
            "frame {i}: volume {volume} vs {rest_volume}"
        );
    }
}

#[test]
fn labels_names_and_params_line_up() {
    let config = small();
    let data = generate(&config).unwrap();
    let n = 2 * config.meshes_per_label;
    assert_eq!(data.set.len(), n);
    assert_eq!(data.params.len(), n);
    let labels = data.set.labels().unwrap();
    assert_eq!(data.set.distinct_labels().unwrap(), ["bend", "twist"]);
    for (i, p) in data.params.iter().enumerate() {
        assert_eq!(data.set.names()[i], format!("{i:04}"));
        assert_eq!(labels[i], p.label.as_str());
        // Alternating labels, and one kind of deformation per frame.
        let expected = if i % 2 == 0 {
            ShapeKind::Bend
        } else {
            ShapeKind::Twist
        };
        assert_eq!(p.label, expected);
        match p.label {
            ShapeKind::Bend => assert_eq!(p.twist, 0.0),
            ShapeKind::Twist => assert_eq!((p.bend, p.bend_azimuth), (0.0, 0.0)),
        }
    }
    assert_eq!(data.params[0], ShapeParams::rest());
    let rest = rest_capsule(&config);
    assert_eq!(data.set.template(), rest);
    // Each frame is exactly `deform(rest, params[i])`.
    for (i, p) in data.params.iter().enumerate() {
        assert_eq!(data.set.mesh(i), deform(&rest, p, &config), "frame {i}");
    }
}

#[test]
fn amplitudes_span_the_range() {
    let config = SynthConfig::default();
    let data = generate(&config).unwrap();
    let (max_twist, max_bend) = (config.max_twist, config.max_bend);
    let twists: Vec<f32> = data
        .params
        .iter()
        .filter(|p| p.label == ShapeKind::Twist)
        .map(|p| p.twist)
        .collect();
    let bends: Vec<f32> = data
        .params
        .iter()
        .filter(|p| p.label == ShapeKind::Bend)
        .map(|p| p.bend)
        .collect();
    assert_eq!((twists.len(), bends.len()), (40, 40));
    assert!(twists.iter().chain(&bends).all(|a| a.is_finite()));
    assert!(twists.iter().all(|t| t.abs() <= max_twist));
    assert!(bends.iter().all(|b| b.abs() <= max_bend));
    assert!(
        twists
            .iter()
            .filter(|t| t.abs() > std::f32::consts::PI)
            .count()
            >= 20
    );
    assert!(twists.iter().any(|&t| t > 0.95 * max_twist));
    assert!(twists.iter().any(|&t| t < -0.95 * max_twist));
    assert!(bends.iter().any(|&b| b > 0.9 * max_bend));
    assert!(bends.iter().any(|&b| b < -0.9 * max_bend));
    let azimuths = data
        .params
        .iter()
        .filter(|p| p.bend != 0.0)
        .map(|p| p.bend_azimuth);
    assert!(
        azimuths
            .clone()
            .all(|a| (0.0..std::f32::consts::PI).contains(&a))
    );
    assert!(azimuths.clone().any(|a| a > 2.0) && azimuths.clone().any(|a| a < 1.0));
}

#[test]
fn twist_turns_the_top_cap_by_theta_relative_to_the_bottom() {
    let config = small();
    let data = generate(&config).unwrap();
    let rest = data.set.frame(0);
    let caps = config.cap_rings;
    let last = ring_count(&config) - 1;
    let mut checked = 0;
    let explicit = [4.0, -4.0, 3.0 * PI, -3.0 * PI, 5.5, 0.3].map(|t| ShapeParams {
        label: ShapeKind::Twist,
        twist: t as f32,
        ..ShapeParams::rest()
    });
    let explicit_meshes = explicit.map(|p| deform(&data.set.template(), &p, &config).positions);
    let generated = (0..data.set.len())
        .filter(|&i| data.params[i].label == ShapeKind::Twist)
        .map(|i| (data.params[i], data.set.frame(i).to_vec()));
    for (p, frame) in explicit.into_iter().zip(explicit_meshes).chain(generated) {
        let turns = ring_rotations(rest, &frame, &config);
        let theta = p.twist as f64;
        // The caps turn rigidly: every ring of a cap by the same angle.
        for k in 0..=caps {
            assert!((turns[k] - turns[0]).abs() < 1e-4);
            assert!((turns[last - k] - turns[last]).abs() < 1e-4);
        }
        let measured = turns[last] - turns[0];
        assert!(
            (measured - theta).abs() < 1e-3,
            "twist {theta}: measured {measured}"
        );
        // Linear along the cylinder.
        for (k, turn) in turns.iter().enumerate().take(last - caps).skip(caps) {
            let t = (k - caps) as f64 / (config.rings - 1) as f64;
            assert!((turn - turns[0] - t * theta).abs() < 1e-3);
        }
        // The axis stays put.
        assert_eq!(frame[0], rest[0]);
        checked += 1;
    }
    assert_eq!(checked, 6 + config.meshes_per_label);
}

#[test]
fn bend_keeps_the_axis_length_and_turns_it_by_the_angle() {
    let config = SynthConfig::default();
    let rest = rest_capsule(&config);
    let rest_axis = axis_polyline(&rest.positions, &config);
    let rest_length = polyline_length(&rest_axis);
    let axis_length = config.length as f64 + 2.0 * config.radius as f64;
    assert!((rest_length - axis_length).abs() < 1e-5);
    for (bend, azimuth) in [
        (2.6, 0.0),
        (-2.6, 1.0),
        (1.0, 2.5),
        (0.01, 0.4),
        (-0.5, 3.0),
    ] {
        let params = ShapeParams {
            bend,
            bend_azimuth: azimuth,
            ..ShapeParams::rest()
        };
        let bent = deform(&rest, &params, &config);
        let axis = axis_polyline(&bent.positions, &config);
        let length = polyline_length(&axis);
        assert!(
            (length / rest_length - 1.0).abs() < 1e-3,
            "bend {bend}: axis {length} vs {rest_length}"
        );
        // The axis turns by |bend| end to end, toward the azimuth, and stays in its plane.
        let first = sub(axis[1], axis[0]);
        let last = sub(axis[axis.len() - 1], axis[axis.len() - 2]);
        let turn = (dot(first, last) / (norm(first) * norm(last)))
            .clamp(-1.0, 1.0)
            .acos();
        assert!(
            (turn - bend.abs() as f64).abs() < 0.02,
            "bend {bend}: turn {turn}"
        );
        let (s, c) = (azimuth as f64).sin_cos();
        let mid = axis[axis.len() / 2];
        let ends = [axis[0], axis[axis.len() - 1]].map(|p| sub(p, mid));
        for e in ends {
            // The ends move toward +d for a positive bend, −d for a negative one.
            assert!((c * e[0] + s * e[1]) * bend as f64 > 0.0);
        }
        for p in &axis {
            assert!(
                (-s * p[0] + c * p[1]).abs() < 1e-5,
                "axis leaves the bending plane"
            );
        }
        assert_closed_genus0(&bent.positions, &bent.faces, "bent");
    }
}

#[test]
fn edges_stretch_within_a_sane_ratio() {
    let config = SynthConfig::default();
    let rest = rest_capsule(&config);
    let (t, b) = (config.max_twist, config.max_bend);
    let cases = [(b, 0.0), (-b, 0.0), (0.0, t), (0.0, -t), (0.3 * b, 0.3 * t)];
    for (bend, twist) in cases {
        let params = ShapeParams {
            bend,
            bend_azimuth: 0.7,
            twist,
            ..ShapeParams::rest()
        };
        let frame = deform(&rest, &params, &config);
        let (lo, hi) = edge_ratio_range(&rest.positions, &frame.positions, &rest.faces);
        assert!(
            lo > 0.5 && hi < 2.5,
            "bend {bend}, twist {twist}: ratios {lo}..{hi}"
        );
        assert!(signed_volume(&frame.positions, &frame.faces) > 0.0);
        assert_closed_genus0(&frame.positions, &frame.faces, "combined");
    }
    // The rest deformed by nothing is the rest, bit for bit.
    assert_eq!(deform(&rest, &ShapeParams::rest(), &config), rest);
}

#[test]
fn invalid_configs_name_the_field() {
    let cases: Vec<(&str, SynthConfig)> = vec![
        (
            "meshes_per_label",
            SynthConfig {
                meshes_per_label: 0,
                ..Default::default()
            },
        ),
        (
            "rings",
            SynthConfig {
                rings: 0,
                ..Default::default()
            },
        ),
        (
            "rings",
            SynthConfig {
                rings: 1,
                ..Default::default()
            },
        ),
        (
            "segments",
            SynthConfig {
                segments: 2,
                ..Default::default()
            },
        ),
        (
            "length",
            SynthConfig {
                length: 0.0,
                ..Default::default()
            },
        ),
        (
            "length",
            SynthConfig {
                length: f32::NAN,
                ..Default::default()
            },
        ),
        (
            "radius",
            SynthConfig {
                radius: -1.0,
                ..Default::default()
            },
        ),
        (
            "radius",
            SynthConfig {
                radius: f32::INFINITY,
                ..Default::default()
            },
        ),
        (
            "max_bend",
            SynthConfig {
                max_bend: f32::NAN,
                ..Default::default()
            },
        ),
        (
            "max_bend",
            SynthConfig {
                max_bend: -0.1,
                ..Default::default()
            },
        ),
        (
            "max_bend",
            SynthConfig {
                max_bend: 10.0,
                ..Default::default()
            },
        ),
        (
            "max_twist",
            SynthConfig {
                max_twist: f32::INFINITY,
                ..Default::default()
            },
        ),
        (
            "segments",
            SynthConfig {
                segments: 1 << 30,
                ..Default::default()
            },
        ),
        (
            "meshes_per_label",
            SynthConfig {
                meshes_per_label: 1 << 20,
                ..Default::default()
            },
        ),
    ];
    for (field, config) in cases {
        match generate(&config) {
            Err(MeshIoError::InvalidArgument { argument, message }) => {
                assert_eq!(argument, field, "{message}");
                assert!(!message.is_empty());
            }
            other => panic!("{field}: expected InvalidArgument, got {other:?}"),
        }
    }
    // The smallest valid config works, and rest_capsule clamps rather than panics.
    let tiny = SynthConfig {
        meshes_per_label: 1,
        rings: 2,
        segments: 3,
        cap_rings: 0,
        ..Default::default()
    };
    let data = generate(&tiny).unwrap();
    assert_eq!(data.set.len(), 2);
    assert_closed_genus0(data.set.frame(1), data.set.faces(), "tiny");
    let clamped = rest_capsule(&SynthConfig {
        rings: 0,
        segments: 0,
        ..tiny
    });
    assert_eq!(clamped.vertex_count(), 2 + 3 * 2);
}
