//! Round trips of the real data sets through normalisation and f32 storage. Skipped (with a
//! message) when the data sets are absent. To stay within a few seconds in a debug build, samba
//! uses every 5th frame and elephant-gallop every 6th (the full figures come from
//! `meshvae roundtrip … --json` in release, see docs/benchmarks.md, "deform-features").

use deform_features::{FeatureExtractor, FeatureOptions, Normalization, Reconstructor};
use mesh_io::MeshSet;

/// Per-vertex Euclidean distances after aligning centroids, RMS over all vertices of all
/// frames, each frame's distances divided by its bounding-box diagonal.
fn rms_rel(set: &MeshSet, options: FeatureOptions) -> f64 {
    let ex = FeatureExtractor::for_set(set, options).unwrap();
    let out = ex.extract(set).unwrap();
    let n = Normalization::fit([&out.features]).unwrap();
    let raw = n.invert(&n.apply(&out.features));
    let meshes = Reconstructor::new(ex.rest())
        .unwrap()
        .reconstruct_all(&raw)
        .unwrap();
    let (mut sum, mut count) = (0.0, 0.0);
    for (f, m) in meshes.iter().enumerate() {
        let o: Vec<[f64; 3]> = set.frame(f).iter().map(|p| p.map(f64::from)).collect();
        let k = o.len() as f64;
        let c1 = m.iter().fold([0.0; 3], |a, p| {
            [a[0] + p[0] / k, a[1] + p[1] / k, a[2] + p[2] / k]
        });
        let c2 = o.iter().fold([0.0; 3], |a, p| {
            [a[0] + p[0] / k, a[1] + p[1] / k, a[2] + p[2] / k]
        });
        let d2 = mesh_io::bbox_diagonal(set.frame(f)).powi(2);
        for (a, b) in m.iter().zip(&o) {
            sum += (0..3)
                .map(|i| ((a[i] - c1[i]) - (b[i] - c2[i])).powi(2))
                .sum::<f64>()
                / d2;
            count += 1.0;
        }
    }
    (sum / count).sqrt()
}

fn load(name: &str, step: usize) -> Option<MeshSet> {
    let dir = mesh_io::datasets::find_or_skip(name)?;
    let set = mesh_io::load_set(&dir).unwrap().value;
    let frames: Vec<usize> = (0..set.len()).step_by(step).collect();
    Some(set.subset(&frames).unwrap())
}

fn check(name: &str, step: usize, plain_bound: f64) {
    let Some(set) = load(name, step) else { return };
    let exact = rms_rel(&set, FeatureOptions::default());
    assert!(
        exact < 1e-6,
        "{name}: rms_rel {exact:e} with the integrability correction"
    );
    let plain = FeatureOptions {
        integrable: false,
        ..Default::default()
    };
    let floor = rms_rel(&set, plain);
    assert!(floor <= plain_bound, "{name}: plain rms_rel {floor:e}");
    eprintln!("{name}: rms_rel {exact:.3e} (exact), {floor:.3e} (plain fit)");
}

#[test]
fn horse_gallop_round_trips() {
    // The plain per-vertex fit's floor here is ≈ 1.9e-3 (≈ 1.1e-3 per coordinate).
    check("horse-gallop", 1, 2e-3);
}

#[test]
fn samba_round_trips() {
    check("samba", 5, 5e-4);
}

#[test]
fn elephant_gallop_round_trips() {
    check("elephant-gallop", 6, 5e-4);
}

#[test]
fn horse_rest_frame_features_are_the_identity() {
    let Some(set) = load("horse-gallop", 47) else {
        return;
    };
    let ex = FeatureExtractor::for_set(&set, FeatureOptions::default()).unwrap();
    let (features, _) = ex.frame_features(set.frame(0)).unwrap();
    let identity = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0];
    for f in &features {
        for (x, e) in f.iter().zip(identity) {
            assert!((x - e).abs() < 1e-6, "{f:?}");
        }
    }
}
