//! Acceptance tests on synthetic meshes: rest features, affine exactness, the twisted tube,
//! degenerate input, and the full path through normalisation, f32 and a features file.

mod common;

use common::shapes::{flat_grid, sphere, tube, twist};
use deform_features::consistency::max_neighbour_jump;
use deform_features::rotation::{Mat3, exp_rotation, mul_vec, norm, scale};
use deform_features::{
    FeatureExtractor, FeatureFile, FeatureOptions, FeatureSet, Normalization, Reconstructor,
    RestMesh, load_features, save_features,
};
use mesh_io::{Face, MeshSet, Point, TriMesh};
use std::f64::consts::PI;

/// A closed, bumpy surface: curved everywhere, so one-rings are never flat.
fn bumpy_sphere() -> (Vec<Point>, Vec<Face>) {
    let (mut p, f) = sphere(10, 16);
    for q in &mut p {
        let (x, y, z) = (q[0], q[1], q[2]);
        let r = 1.0 + 0.15 * (3.0 * x).sin() * (2.0 * y).cos() + 0.1 * z * z;
        *q = [1.3 * x * r, y * r, 0.8 * z * r];
    }
    (p, f)
}

fn set_of(rest: &[Point], frames: &[Vec<Point>], faces: &[Face]) -> MeshSet {
    let mut meshes = vec![TriMesh {
        positions: rest.to_vec(),
        faces: faces.to_vec(),
    }];
    meshes.extend(frames.iter().map(|p| TriMesh {
        positions: p.clone(),
        faces: faces.to_vec(),
    }));
    let names = (0..meshes.len()).map(|i| format!("f{i}")).collect();
    MeshSet::from_meshes(meshes, names).unwrap()
}

/// Round trip of every frame through normalisation and f32, with the per-frame RMS and max
/// distances (centroids aligned) divided by the frame's bounding-box diagonal.
fn round_trip(set: &MeshSet, options: FeatureOptions) -> Vec<(f64, f64)> {
    let extractor = FeatureExtractor::for_set(set, options).unwrap();
    let features = extractor.extract(set).unwrap().features;
    let norm_ = Normalization::fit([&features]).unwrap();
    let stored = norm_.apply(&features);
    let raw = norm_.invert(&stored);
    let rec = Reconstructor::new(extractor.rest()).unwrap();
    let meshes = rec.reconstruct_all(&raw).unwrap();
    meshes
        .iter()
        .enumerate()
        .map(|(f, m)| frame_error(m, set.frame(f)))
        .collect()
}

fn frame_error(rec: &[[f64; 3]], original: &[Point]) -> (f64, f64) {
    let n = rec.len() as f64;
    let c1 = rec.iter().fold([0.0; 3], |a, p| {
        [a[0] + p[0] / n, a[1] + p[1] / n, a[2] + p[2] / n]
    });
    let o: Vec<[f64; 3]> = original.iter().map(|p| p.map(f64::from)).collect();
    let c2 = o.iter().fold([0.0; 3], |a, p| {
        [a[0] + p[0] / n, a[1] + p[1] / n, a[2] + p[2] / n]
    });
    let d: Vec<f64> = rec
        .iter()
        .zip(&o)
        .map(|(a, b)| {
            (0..3)
                .map(|k| ((a[k] - c1[k]) - (b[k] - c2[k])).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let diag = mesh_io::bbox_diagonal(original);
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    (rms / diag, d.iter().fold(0.0f64, |a, &b| a.max(b)) / diag)
}

fn transform(points: &[Point], a: &Mat3, t: [f64; 3]) -> Vec<Point> {
    points
        .iter()
        .map(|p| {
            let q = mul_vec(a, p.map(f64::from));
            [
                (q[0] + t[0]) as f32,
                (q[1] + t[1]) as f32,
                (q[2] + t[2]) as f32,
            ]
        })
        .collect()
}

/// Deterministic pseudo-random numbers in [−1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
    fn unit(&mut self) -> [f64; 3] {
        let v = [self.next(), self.next(), self.next()];
        scale(v, 1.0 / norm(v))
    }
}

#[test]
fn rest_mesh_features_are_zero_rotation_and_identity_stretch() {
    for (pos, faces) in [bumpy_sphere(), flat_grid(9, 7, 0.5)] {
        let set = set_of(&pos, std::slice::from_ref(&pos), &faces);
        for integrable in [false, true] {
            let options = FeatureOptions {
                integrable,
                ..Default::default()
            };
            let out = FeatureExtractor::for_set(&set, options)
                .unwrap()
                .extract(&set)
                .unwrap();
            let identity = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0];
            for (x, e) in out.features.as_slice().iter().zip(identity.iter().cycle()) {
                assert!((x - e).abs() < 1e-6, "{x} vs {e}");
            }
            assert!(out.warnings.is_empty(), "{:?}", out.warnings);
        }
    }
}

#[test]
fn rigid_motions_and_affine_maps_round_trip_exactly() {
    let mut rng = Rng(0x5eed);
    for (pos, faces) in [bumpy_sphere(), flat_grid(10, 8, 0.7)] {
        let mut frames = Vec::new();
        // Rotations by 0.5 to 4 rad (past 180°) about random axes, with translations.
        for angle in [0.5, 2.0, PI - 1e-4, PI, 3.6, 4.0] {
            let r = exp_rotation(scale(rng.unit(), angle));
            frames.push(transform(&pos, &r, [rng.next() * 5.0, rng.next(), 2.0]));
        }
        // General affine maps: random matrices kept well away from singular.
        for _ in 0..4 {
            let mut a = exp_rotation(scale(rng.unit(), 2.5 * rng.next()));
            for (r, row) in a.iter_mut().enumerate() {
                for (c, x) in row.iter_mut().enumerate() {
                    *x =
                        *x * (1.2 + 0.4 * rng.next()) + if r == c { 0.0 } else { 0.3 * rng.next() };
                }
            }
            assert!(deform_features::rotation::det(&a).abs() > 0.2);
            frames.push(transform(&pos, &a, [rng.next(), rng.next(), rng.next()]));
        }
        let set = set_of(&pos, &frames, &faces);
        for (f, (rms, max)) in round_trip(&set, FeatureOptions::default())
            .iter()
            .enumerate()
        {
            assert!(*max < 1e-6, "frame {f}: rms {rms:e}, max {max:e}");
        }
    }
}

/// Errors in mesh units follow the set's scale: a set scaled by s about the origin has the same
/// features, and any feature array (a network's imperfect output included) reconstructs to s
/// times the unscaled set's mesh. So a model trained on a rescaled copy of a data set is the same
/// model, and its errors are s times those on the original files: published absolute errors
/// compare with ours only after converting units.
#[test]
fn a_uniformly_scaled_set_has_the_same_features_and_scaled_reconstructions() {
    let s = 1.676_881_5;
    let (pos, faces) = bumpy_sphere();
    // A non-affine pose: each point turned about z by an angle growing with its height.
    let bent: Vec<Point> = pos
        .iter()
        .map(|p| {
            let r = exp_rotation([0.0, 0.0, 0.6 * f64::from(p[2])]);
            let q = mul_vec(&r, p.map(f64::from));
            [q[0] as f32, q[1] as f32, (q[2] * 1.1) as f32]
        })
        .collect();
    let scaled = |points: &[Point]| -> Vec<Point> {
        points
            .iter()
            .map(|p| p.map(|x| (f64::from(x) * s) as f32))
            .collect()
    };
    let options = FeatureOptions::default();
    let features_of = |rest: &[Point], frame: &[Point]| {
        let set = set_of(rest, &[frame.to_vec()], &faces);
        let extractor = FeatureExtractor::for_set(&set, options).unwrap();
        let features = extractor.extract(&set).unwrap().features;
        (features, Reconstructor::new(extractor.rest()).unwrap())
    };
    let (f1, rec1) = features_of(&pos, &bent);
    let (f2, rec2) = features_of(&scaled(&pos), &scaled(&bent));
    let largest = f1.frame(1).iter().fold(0.0f32, |a, x| a.max(x.abs()));
    let differ = f1
        .frame(1)
        .iter()
        .zip(f2.frame(1))
        .fold(0.0f32, |a, (x, y)| a.max((x - y).abs()));
    assert!(
        largest > 0.1 && differ < 1e-4 * largest,
        "features differ by {differ}"
    );
    // A "network output": the features, off by a smooth error.
    let output: Vec<f32> = f1
        .frame(1)
        .iter()
        .enumerate()
        .map(|(i, x)| x + 0.05 * ((i / 9) as f32 * 0.37).sin() * ((i % 9) as f32 - 4.0) / 4.0)
        .collect();
    let mesh1 = rec1.reconstruct(&output).unwrap();
    let mesh2 = rec2.reconstruct(&output).unwrap();
    let error1 = frame_error(&mesh1, &bent).0 * mesh_io::bbox_diagonal(&bent);
    assert!(
        error1 > 1e-3,
        "the perturbed output is not a copy of the pose ({error1})"
    );
    let worst = mesh1.iter().zip(&mesh2).fold(0.0f64, |a, (p, q)| {
        (0..3).fold(a, |a, k| a.max((q[k] - s * p[k]).abs()))
    });
    assert!(worst < 1e-5, "scaled reconstruction off by {worst}");
}

#[test]
fn similarities_are_fitted_exactly_without_the_correction() {
    // The plain per-vertex fit returns the similarity's own linear part at every vertex.
    let (pos, faces) = bumpy_sphere();
    let rest = RestMesh::new(&pos, &faces).unwrap();
    let options = FeatureOptions {
        integrable: false,
        ..Default::default()
    };
    let ex = FeatureExtractor::new(rest, options).unwrap();
    let mut a = exp_rotation([2.0, -1.0, 1.5]);
    a.iter_mut().flatten().for_each(|x| *x *= 1.7);
    for t in ex.gradients(&transform(&pos, &a, [1.0, 2.0, 3.0])).unwrap() {
        for r in 0..3 {
            for c in 0..3 {
                assert!((t[r][c] - a[r][c]).abs() < 1e-5, "{t:?}");
            }
        }
    }
}

/// A thin tube twisted by 3π along z. Thin on purpose: twisting shears the surface, which tilts
/// every rotation by ≈ radius·twist-rate/2 about the radial axis; where the twist passes 2π the
/// rotation is then *near* (not at) the identity and its axis swings from +z to −z within a ring
/// spacing. A smooth field of rotation vectors exists only when that tilt is small next to the
/// twist per ring (radius ≪ ring spacing / 16); see the `consistency` module's notes.
fn twisted_tube() -> (MeshSet, Vec<Point>) {
    let length = 10.0;
    let (pos, faces) = tube(8, 51, 0.002, length);
    let twisted = twist(&pos, 3.0 * PI, length as f64);
    (
        set_of(&pos, std::slice::from_ref(&twisted), &faces),
        twisted,
    )
}

fn rotation_field(ex: &FeatureExtractor, frame: &[Point]) -> Vec<[f64; 3]> {
    let (f, warnings) = ex.frame_features(frame).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    f.iter().map(|x| [x[0], x[1], x[2]]).collect()
}

#[test]
fn twisted_tube_rotations_are_smooth_and_round_trip() {
    let (set, twisted) = twisted_tube();
    let ex = FeatureExtractor::for_set(&set, FeatureOptions::default()).unwrap();
    let omega = rotation_field(&ex, &twisted);
    let jump = max_neighbour_jump(ex.rest(), &omega);
    assert!(jump < PI / 8.0, "max neighbour difference {jump}");
    // The field really winds past π and 2π (the vectors reach |ω| ≈ 2π + π... or −2π..π).
    let span = omega.iter().map(|w| w[2]).fold(f64::NEG_INFINITY, f64::max)
        - omega.iter().map(|w| w[2]).fold(f64::INFINITY, f64::min);
    assert!(span > 2.5 * PI, "z-component span {span}");
    for (rms, _) in round_trip(&set, FeatureOptions::default()) {
        assert!(rms <= 1e-3, "rms_rel {rms}");
    }
    let plain = FeatureOptions {
        integrable: false,
        ..Default::default()
    };
    for (rms, _) in round_trip(&set, plain) {
        assert!(rms <= 1e-3, "plain rms_rel {rms}");
    }
}

#[test]
fn twisted_tube_without_consistency_jumps() {
    let (set, twisted) = twisted_tube();
    let options = FeatureOptions {
        consistent_rotations: false,
        ..Default::default()
    };
    let ex = FeatureExtractor::for_set(&set, options).unwrap();
    let omega = rotation_field(&ex, &twisted);
    // Principal vectors flip from ≈ +π z to ≈ −π z where the twist passes π.
    let jump = max_neighbour_jump(ex.rest(), &omega);
    assert!(jump > PI / 4.0, "max neighbour difference {jump}");
    assert!(omega.iter().all(|w| norm(*w) <= PI + 1e-9));
}

#[test]
fn degenerate_input_gives_finite_features_and_warnings() {
    let (mut pos, mut faces) = flat_grid(6, 6, 0.3);
    // Two vertices at the same position (an interior one moved onto its neighbour) …
    pos[14] = pos[15];
    // … and a zero-area triangle (collinear corners) glued to the boundary.
    let n = pos.len() as u32;
    pos.push([0.5, -0.2, 0.0]);
    pos.push([1.0, -0.2, 0.0]);
    pos.push([1.5, -0.2, 0.0]);
    faces.push([n, n + 1, n + 2]);
    let deformed: Vec<Point> = pos
        .iter()
        .map(|p| [p[0] * 1.1, p[1] + 0.2 * p[0] * p[0], p[2] - 0.1 * p[1]])
        .collect();
    let mut collapsed = deformed.clone();
    collapsed[8] = collapsed[9]; // and a frame where a ring collapses
    let set = set_of(&pos, &[deformed, collapsed], &faces);
    for options in [
        FeatureOptions::default(),
        FeatureOptions {
            integrable: false,
            ..Default::default()
        },
    ] {
        let ex = FeatureExtractor::for_set(&set, options).unwrap();
        let out = ex.extract(&set).unwrap();
        assert!(out.features.as_slice().iter().all(|x| x.is_finite()));
        assert!(
            out.warnings.iter().any(|w| w.contains("zero area")),
            "{:?}",
            out.warnings
        );
        let rec = Reconstructor::new(ex.rest()).unwrap();
        for m in rec.reconstruct_all(&out.features).unwrap() {
            assert!(m.iter().flatten().all(|x| x.is_finite()));
        }
    }
}

#[test]
fn features_file_keeps_what_the_round_trip_needs() {
    let (pos, faces) = bumpy_sphere();
    let a = exp_rotation([0.3, 0.2, -0.4]);
    let set = set_of(&pos, &[transform(&pos, &a, [0.0; 3])], &faces);
    let out = deform_features::extract_features(&set, FeatureOptions::default()).unwrap();
    let n = Normalization::fit([&out.features]).unwrap();
    let file = FeatureFile {
        features: n.apply(&out.features),
        normalized: true,
        normalization: Some(n),
        names: set.names().to_vec(),
        rest_positions: Some(pos.clone()),
        faces: Some(faces.clone()),
        extra: Default::default(),
    };
    let path = std::env::temp_dir().join(format!(
        "deform-acceptance-{}.safetensors",
        std::process::id()
    ));
    save_features(&path, &file).unwrap();
    let back = load_features(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    // Rebuild everything from the file alone.
    let rest = RestMesh::new(
        back.rest_positions.as_ref().unwrap(),
        back.faces.as_ref().unwrap(),
    )
    .unwrap();
    let raw: FeatureSet = back.normalization.unwrap().invert(&back.features);
    let m = Reconstructor::new(&rest)
        .unwrap()
        .reconstruct(raw.frame(1))
        .unwrap();
    let (rms, _) = frame_error(&m, set.frame(1));
    assert!(rms < 1e-6, "{rms}");
}
