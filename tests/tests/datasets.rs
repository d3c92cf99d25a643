//! The real data sets through mesh-io: caches, and the horse pair that makes a labelled set.

use mesh_io::{MeshSet, datasets};

fn bits(set: &MeshSet) -> Vec<u32> {
    set.positions()
        .iter()
        .flatten()
        .map(|x| x.to_bits())
        .collect()
}

#[test]
fn cache_round_trip_is_bit_exact_on_real_sets() {
    for name in ["horse-gallop", "samba"] {
        let Some(dir) = datasets::find_or_skip(name) else {
            continue;
        };
        let set = mesh_io::load_set(&dir).unwrap().value;
        let path = std::env::temp_dir().join(format!("e2e-{name}-{}.mvset", std::process::id()));
        mesh_io::cache::write_cache(&path, &set).unwrap();
        let back = mesh_io::load_set(&path).unwrap().value;
        std::fs::remove_file(&path).unwrap();
        assert_eq!(back.faces(), set.faces(), "{name}");
        assert_eq!(back.names(), set.names(), "{name}");
        assert_eq!(bits(&back), bits(&set), "{name}");
    }
}

#[test]
fn horse_gallop_and_poses_share_one_connectivity() {
    let (Some(gallop), Some(poses)) = (
        datasets::find_or_skip("horse-gallop"),
        datasets::find_or_skip("horse-poses"),
    ) else {
        return;
    };
    let mut files = mesh_io::set::list_mesh_files(&gallop).unwrap();
    files.extend(mesh_io::set::list_mesh_files(&poses).unwrap());
    let set = mesh_io::load_files(&files).unwrap().value;
    assert_eq!(set.len(), 58);
    assert_eq!(set.names()[0], "0001");
    assert_eq!(set.names()[48], "1");
    assert_eq!(set.names()[57], "10");
    let labels = (0..58)
        .map(|i| if i < 48 { "gallop" } else { "pose" }.to_string())
        .collect();
    let set = set.with_labels(labels).unwrap();
    assert_eq!(set.distinct_labels().unwrap(), ["gallop", "pose"]);
}
