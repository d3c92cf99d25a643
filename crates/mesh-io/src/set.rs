//! Loading a [`MeshSet`] from a folder, a list of files, a multi-frame glTF or a cache file.

use crate::error::{MeshIoError, Result, Warning};
use crate::format::{MeshFormat, read_mesh};
use crate::mesh::{MeshSet, TriMesh, check_same_connectivity};
use crate::{Loaded, cache, glb, labels};
use rayon::prelude::*;
use std::cmp::Ordering;
use std::path::{Path, PathBuf};

/// The labels file picked up automatically from a set's folder.
pub const LABELS_FILE: &str = "labels.csv";

/// Loads a set from whatever `path` is: a folder of mesh files, a multi-frame `.glb`/`.gltf`,
/// or a `.mvset` cache.
pub fn load_set(path: &Path) -> Result<Loaded<MeshSet>> {
    if path.is_dir() {
        return load_folder(path);
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("mvset") => cache::read_cache(path).map(Loaded::new),
        Some("glb" | "gltf") => glb::read_gltf_set(path),
        _ if !path.exists() => Err(MeshIoError::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or folder"),
        )),
        _ => Err(MeshIoError::InvalidArgument {
            argument: "SET",
            message: format!(
                "{} is neither a folder of meshes, a .glb/.gltf file nor a .mvset cache",
                path.display()
            ),
        }),
    }
}

/// Loads every mesh file of `dir` (natural order: `2.obj` before `10.obj`), and `labels.csv`
/// from the same folder when present.
pub fn load_folder(dir: &Path) -> Result<Loaded<MeshSet>> {
    let files = list_mesh_files(dir)?;
    if files.is_empty() {
        return Err(MeshIoError::EmptySet { path: dir.into() });
    }
    let mut loaded = load_files_named(&files, dir)?;
    let labels_path = dir.join(LABELS_FILE);
    if labels_path.is_file() {
        let set = loaded.value;
        let labels = labels::read_labels(&labels_path, set.names())?;
        loaded.value = set.with_labels(labels)?;
    }
    Ok(loaded)
}

/// Loads the given files, in the given order, as one set.
pub fn load_files(files: &[PathBuf]) -> Result<Loaded<MeshSet>> {
    let origin = files
        .first()
        .map_or_else(|| PathBuf::from("<no files>"), |f| f.clone());
    load_files_named(files, &origin)
}

fn load_files_named(files: &[PathBuf], origin: &Path) -> Result<Loaded<MeshSet>> {
    if files.len() < 2 {
        return Err(MeshIoError::TooFewMeshes {
            path: origin.into(),
            count: files.len(),
        });
    }
    // Parse in parallel, then report the first failure in file order, so the error does not
    // depend on thread timing.
    let meshes: Vec<Result<Loaded<TriMesh>>> = files.par_iter().map(|f| read_mesh(f)).collect();
    let mut warnings: Vec<Warning> = Vec::new();
    let mut frames: Vec<TriMesh> = Vec::with_capacity(files.len());
    for (file, mesh) in files.iter().zip(meshes) {
        let mesh = mesh?;
        warnings.extend(mesh.warnings);
        if let Some(first) = frames.first() {
            check_same_connectivity(first, &files[0], &mesh.value, file)?;
        }
        frames.push(mesh.value);
    }
    let names = frame_names(files, &mut warnings);
    let set = MeshSet::from_meshes(frames, names)?;
    Ok(Loaded {
        value: set,
        warnings,
    })
}

/// Frame names are file stems (`0001` for `0001.obj`), or whole file names where stems collide.
fn frame_names(files: &[PathBuf], warnings: &mut Vec<Warning>) -> Vec<String> {
    let stem = |f: &PathBuf| {
        f.file_stem()
            .map_or(String::new(), |s| s.to_string_lossy().into())
    };
    let stems: Vec<String> = files.iter().map(stem).collect();
    let mut sorted = stems.clone();
    sorted.sort();
    if sorted.windows(2).all(|w| w[0] != w[1]) {
        return stems;
    }
    warnings.push(Warning {
        path: files[0].parent().unwrap_or(Path::new(".")).into(),
        message: "files share a name with different extensions; frames are named by file name"
            .into(),
    });
    files
        .iter()
        .map(|f| {
            f.file_name()
                .map_or(String::new(), |s| s.to_string_lossy().into())
        })
        .collect()
}

/// Writes every frame of `set` into `dir` (created if missing) as `<name>.obj`, plus
/// `labels.csv` for a labelled set, so that [`load_folder`] reads the same set back. Returns the
/// paths of the mesh files. Each file is written atomically.
pub fn write_folder(dir: &Path, set: &MeshSet) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| MeshIoError::io(dir, e))?;
    let files: Vec<PathBuf> = set
        .names()
        .iter()
        .map(|n| dir.join(format!("{n}.obj")))
        .collect();
    files
        .par_iter()
        .enumerate()
        .try_for_each(|(i, f)| crate::obj::write_obj(f, &set.mesh(i)))?;
    if let Some(labels) = set.labels() {
        let names: Vec<String> = files
            .iter()
            .map(|f| {
                f.file_name()
                    .map_or(String::new(), |n| n.to_string_lossy().into())
            })
            .collect();
        labels::write_labels(&dir.join(LABELS_FILE), &names, labels)?;
    }
    Ok(files)
}

/// The mesh files directly inside `dir` (hidden files skipped), in natural order.
pub fn list_mesh_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| MeshIoError::io(dir, e))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| MeshIoError::io(dir, e))?.path();
        let hidden = path
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'));
        if !hidden && path.is_file() && MeshFormat::from_path(&path).is_some() {
            files.push(path);
        }
    }
    files.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
    Ok(files)
}

/// Natural string order: runs of digits compare as numbers (`2` < `10`), the rest as text.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return Ordering::Equal,
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let da = a.iter().take_while(|c| c.is_ascii_digit()).count();
                let db = b.iter().take_while(|c| c.is_ascii_digit()).count();
                let (na, nb) = (trim_zeros(&a[..da]), trim_zeros(&b[..db]));
                let ord = na
                    .len()
                    .cmp(&nb.len())
                    .then_with(|| na.cmp(nb))
                    .then(da.cmp(&db));
                if ord != Ordering::Equal {
                    return ord;
                }
                a = &a[da..];
                b = &b[db..];
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                a = &a[1..];
                b = &b[1..];
            }
        }
    }
}

fn trim_zeros(digits: &[u8]) -> &[u8] {
    let zeros = digits.iter().take_while(|&&c| c == b'0').count();
    &digits[zeros..]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folder_round_trip_keeps_order_names_and_labels() {
        let dir = std::env::temp_dir().join(format!("mesh-io-folder-{}", std::process::id()));
        let faces = vec![[0, 1, 2], [0, 2, 3]];
        let names: Vec<String> = ["1", "2", "10"].map(String::from).to_vec();
        let positions = (0..12)
            .map(|i| [i as f32, 0.5, -(i as f32) / 3.0])
            .collect();
        let set = MeshSet::from_flat(faces, 4, positions, names)
            .unwrap()
            .with_labels(["a", "b", "a"].map(String::from).to_vec())
            .unwrap();
        write_folder(&dir, &set).unwrap();
        let back = load_folder(&dir).unwrap().value;
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(back, set);
    }

    #[test]
    fn natural_order() {
        let mut v = vec![
            "10.obj",
            "2.obj",
            "1.obj",
            "mesh_0002.obj",
            "mesh_0010.obj",
            "a.obj",
        ];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            v,
            [
                "1.obj",
                "2.obj",
                "10.obj",
                "a.obj",
                "mesh_0002.obj",
                "mesh_0010.obj"
            ]
        );
        assert_eq!(natural_cmp("01", "1"), Ordering::Greater);
        assert_eq!(natural_cmp("x9y", "x10y"), Ordering::Less);
    }
}
