//! The gallop sets store their 24-frame cycle twice (elephant-gallop all but its last frame);
//! samba and horse-poses repeat no shape.
//! Skips, saying so, where the data sets are absent.

use mesh_io::{ShapeGroups, datasets, load_set};

fn groups(name: &str) -> Option<(usize, Vec<Vec<usize>>)> {
    let dir = datasets::find_or_skip(name)?;
    let set = load_set(&dir).unwrap().value;
    let g = set.shape_groups(ShapeGroups::DEFAULT_TOLERANCE).unwrap();
    Some((set.len(), g.members()))
}

#[test]
fn gallop_cycles_are_stored_twice() {
    // Mesh i and mesh i + 24 (natural file order) are one shape. elephant-gallop's last frames
    // (24.obj and 48.obj, indices 23 and 47) differ as much as neighbouring frames do (0.026 RMS).
    for (name, pairs) in [("horse-gallop", 24), ("elephant-gallop", 23)] {
        let Some((n, members)) = groups(name) else {
            continue;
        };
        eprintln!("{name}: {n} meshes, {} shapes", members.len());
        assert_eq!(n, 48, "{name}");
        let mut expected: Vec<Vec<usize>> = (0..pairs).map(|i| vec![i, i + 24]).collect();
        expected.extend((pairs..24).flat_map(|i| [vec![i], vec![i + 24]]));
        expected.sort();
        assert_eq!(members, expected, "{name}");
    }
}

#[test]
fn dance_and_poses_repeat_no_shape() {
    for name in ["samba", "horse-poses"] {
        if let Some((n, members)) = groups(name) {
            assert_eq!(members.len(), n, "{name}");
        }
    }
}
