//! Labels files: CSV lines `file,label` (an optional `file,label` header; file names with or
//! without extension), one line per mesh of the set.

use crate::atomic::write_atomic;
use crate::error::{MeshIoError, Result};
use std::io::Write;
use std::path::Path;

/// Reads `path` and returns one label per name of `names`, in that order. Every name needs a
/// label and every line must name a mesh of the set.
pub fn read_labels(path: &Path, names: &[String]) -> Result<Vec<String>> {
    let text = std::fs::read_to_string(path).map_err(|e| MeshIoError::io(path, e))?;
    let err = |line: usize, message: String| MeshIoError::Labels {
        path: path.into(),
        line,
        message,
    };
    let mut labels: Vec<Option<String>> = vec![None; names.len()];
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let Some((file, label)) = line.split_once(',') else {
            return Err(err(i + 1, format!("expected `file,label`, found {line:?}")));
        };
        let (file, label) = (file.trim(), label.trim());
        if i == 0 && file.eq_ignore_ascii_case("file") {
            continue;
        }
        if label.is_empty() || label.contains(',') {
            return Err(err(i + 1, format!("bad label {label:?} for {file:?}")));
        }
        let stem = Path::new(file)
            .file_stem()
            .map_or(file.to_string(), |s| s.to_string_lossy().into());
        let Some(k) = names.iter().position(|n| n == file || *n == stem) else {
            return Err(err(i + 1, format!("{file:?} is not a mesh of the set")));
        };
        if labels[k].is_some() {
            return Err(err(i + 1, format!("{file:?} is labelled twice")));
        }
        labels[k] = Some(label.to_string());
    }
    labels
        .into_iter()
        .zip(names)
        .map(|(l, n)| l.ok_or_else(|| err(0, format!("mesh {n:?} has no label"))))
        .collect()
}

/// Writes a labels CSV (`file,label` header, then one line per mesh), atomically.
pub fn write_labels(path: &Path, files: &[String], labels: &[String]) -> Result<()> {
    write_atomic(path, |w| {
        writeln!(w, "file,label")?;
        for (f, l) in files.iter().zip(labels) {
            writeln!(w, "{f},{l}")?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_match_names_with_or_without_extension() {
        let dir = std::env::temp_dir().join(format!("mesh-io-labels-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("labels.csv");
        let names: Vec<String> = ["a", "b"].map(String::from).to_vec();
        std::fs::write(&path, "file,label\nb.obj,pose\na,gallop\n").unwrap();
        assert_eq!(read_labels(&path, &names).unwrap(), ["gallop", "pose"]);
        std::fs::write(&path, "a.obj,gallop\n").unwrap();
        let e = read_labels(&path, &names).unwrap_err().to_string();
        assert!(e.contains("\"b\" has no label"), "{e}");
        std::fs::write(&path, "a.obj,gallop\nb,x\nc.obj,y\n").unwrap();
        let e = read_labels(&path, &names).unwrap_err().to_string();
        assert!(
            e.contains(":3:") && e.contains("not a mesh of the set"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
