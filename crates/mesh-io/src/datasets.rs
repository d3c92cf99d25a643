//! Where the real mesh sets live: `../shared/datasets/<name>` beside the repository, unpacked by
//! `../shared/datasets/unpack`, or any folder named by the `MESHVAE_DATASETS` variable. Tests and
//! benchmarks that need them call [`find`] and skip, saying so, when it returns `None`.

use std::path::{Path, PathBuf};

/// The standard sets, with their expected (meshes, vertices, faces, boundary edges).
pub const KNOWN: &[(&str, usize, usize, usize, usize)] = &[
    ("horse-gallop", 48, 8431, 16843, 19),
    ("horse-poses", 10, 8431, 16843, 19),
    ("samba", 175, 9971, 19938, 0),
    ("elephant-gallop", 48, 42321, 84638, 0),
];

/// The folder holding the unpacked data sets, if one can be found: `$MESHVAE_DATASETS`, else
/// `shared/datasets` beside any ancestor of the current directory.
pub fn root() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os("MESHVAE_DATASETS") {
        return Some(PathBuf::from(dir)).filter(|d| d.is_dir());
    }
    let cwd = std::env::current_dir().ok()?;
    cwd.ancestors()
        .map(|a| a.join("shared").join("datasets"))
        .find(|d| d.is_dir())
}

/// The unpacked folder of set `name` (e.g. `"horse-gallop"`), if present.
pub fn find(name: &str) -> Option<PathBuf> {
    let dir = root()?.join(name);
    has_obj(&dir).then_some(dir)
}

/// Like [`find`], but prints why a test is skipped when the set is absent.
pub fn find_or_skip(name: &str) -> Option<PathBuf> {
    let found = find(name);
    if found.is_none() {
        eprintln!(
            "SKIPPED: data set {name} not found (run ../shared/datasets/unpack, or set MESHVAE_DATASETS)"
        );
    }
    found
}

fn has_obj(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|mut it| {
        it.any(|e| e.is_ok_and(|e| e.path().extension().is_some_and(|x| x == "obj")))
    })
}
