//! One metadata convention for every safetensors file the tool writes (mesh-set caches,
//! features, weights, checkpoints), so that a reader refuses a damaged or foreign file by name
//! instead of loading garbage.
//!
//! Every file's `__metadata__` holds, besides its own entries:
//! - `format`: what the file holds (`meshvae-set`, `meshvae-features`, `meshvae-weights`, …);
//! - `version`: the layout's version, an integer; a reader refuses versions newer than it knows;
//! - `writer`: the tool and version that wrote it (`meshvae 0.1.0`);
//! - `checksum`: `crc32:` and eight hex digits, the CRC-32 (IEEE) of every byte after the header,
//!   i.e. of the tensor data as stored.
//!
//! Files are written atomically and streamed: the header is written with a placeholder
//! checksum, the tensors follow one by one (a lazy tensor is only turned into bytes when its
//! turn comes), and the checksum is patched in place before the rename.
//!
//! ```
//! use mesh_io::stamped::{Entry, Stamp, read_stamped, write_stamped};
//! use safetensors::Dtype;
//! # fn main() -> Result<(), mesh_io::MeshIoError> {
//! let path = std::env::temp_dir().join(format!("stamped-doc-{}.safetensors", std::process::id()));
//! let stamp = Stamp { format: "example", version: 1 };
//! let values: Vec<u8> = [1.0f32, 2.0].iter().flat_map(|x| x.to_le_bytes()).collect();
//! write_stamped(&path, stamp, [("note".into(), "hello".into())].into(), vec![
//!     Entry::new("values", Dtype::F32, vec![2], values),
//! ])?;
//! let bytes = std::fs::read(&path).unwrap();
//! let file = read_stamped(&bytes, &path, stamp)?;
//! assert_eq!(file.metadata["note"], "hello");
//! assert_eq!(file.tensors.tensor("values").unwrap().shape(), &[2]);
//! # std::fs::remove_file(&path).unwrap();
//! # Ok(()) }
//! ```

use crate::atomic::write_atomic;
use crate::error::{MeshIoError, Result};
use safetensors::SafeTensors;
pub use safetensors::tensor::Dtype;
use serde_json::{Map, Value, json};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::io::{Seek, SeekFrom, Write};
use std::path::Path;

/// The `writer` entry of every file this build writes.
pub const WRITER: &str = concat!("meshvae ", env!("CARGO_PKG_VERSION"));

const PLACEHOLDER: &str = "crc32:00000000";

/// What a file holds and the newest layout of it (the version written, and the newest read).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamp {
    pub format: &'static str,
    pub version: u32,
}

type Producer<'a> = Box<dyn FnOnce() -> std::result::Result<Cow<'a, [u8]>, String> + 'a>;

/// One tensor to write: name, element type, shape and its little-endian bytes (given, or
/// produced when written).
pub struct Entry<'a> {
    name: String,
    dtype: Dtype,
    shape: Vec<usize>,
    data: Producer<'a>,
}

impl<'a> Entry<'a> {
    /// A tensor whose bytes are at hand.
    pub fn new(
        name: impl Into<String>,
        dtype: Dtype,
        shape: Vec<usize>,
        bytes: impl Into<Cow<'a, [u8]>>,
    ) -> Self {
        let bytes = bytes.into();
        Self::lazy(name, dtype, shape, move || Ok(bytes))
    }

    /// A tensor whose bytes are made only when it is written (big files never exist twice in
    /// memory). The producer's error message ends the write.
    pub fn lazy(
        name: impl Into<String>,
        dtype: Dtype,
        shape: Vec<usize>,
        bytes: impl FnOnce() -> std::result::Result<Cow<'a, [u8]>, String> + 'a,
    ) -> Self {
        Self {
            name: name.into(),
            dtype,
            shape,
            data: Box::new(bytes),
        }
    }

    fn byte_len(&self) -> usize {
        self.shape.iter().product::<usize>() * self.dtype.bitsize() / 8
    }
}

/// Little-endian bytes of f32 values.
pub fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Little-endian bytes of f64 values.
pub fn f64_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Little-endian bytes of u32 values.
pub fn u32_bytes(values: &[u32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Writes `entries` (in this order) with `metadata` plus the convention's entries to `path`,
/// atomically. Errors: an entry whose bytes do not match its shape, a duplicate name, or I/O,
/// naming `path`.
pub fn write_stamped(
    path: &Path,
    stamp: Stamp,
    metadata: BTreeMap<String, String>,
    entries: Vec<Entry<'_>>,
) -> Result<()> {
    let bad = |message: String| MeshIoError::Tensors {
        path: path.into(),
        message,
    };
    let mut meta: Map<String, Value> = metadata
        .into_iter()
        .map(|(k, v)| (k, Value::String(v)))
        .collect();
    meta.insert("format".into(), stamp.format.into());
    meta.insert("version".into(), stamp.version.to_string().into());
    meta.insert("writer".into(), WRITER.into());
    meta.insert("checksum".into(), PLACEHOLDER.into());
    let mut header = Map::new();
    header.insert("__metadata__".into(), Value::Object(meta));
    let mut offset = 0usize;
    for e in &entries {
        let end = offset + e.byte_len();
        let info = json!({ "dtype": e.dtype, "shape": e.shape, "data_offsets": [offset, end] });
        if header.insert(e.name.clone(), info).is_some() || e.name == "__metadata__" {
            return Err(bad(format!("tensor name {:?} given twice", e.name)));
        }
        offset = end;
    }
    let mut head = serde_json::to_vec(&Value::Object(header)).map_err(|e| bad(e.to_string()))?;
    // The data starts 8-aligned, as the format recommends: pad the header with spaces.
    while head.len() % 8 != 0 {
        head.push(b' ');
    }
    let needle = format!("\"checksum\":\"{PLACEHOLDER}\"");
    let at = find(&head, needle.as_bytes())
        .map(|i| 8 + i + needle.len() - 9)
        .ok_or_else(|| bad("checksum placeholder lost in the header".into()))?;
    let mut failure = None;
    let written = write_atomic(path, |w| {
        w.write_all(&(head.len() as u64).to_le_bytes())?;
        w.write_all(&head)?;
        let mut crc = crc32fast::Hasher::new();
        for e in entries {
            let (name, expected) = (e.name.clone(), e.byte_len());
            let bytes = match (e.data)() {
                Ok(b) if b.len() == expected => b,
                Ok(b) => {
                    failure = Some(format!(
                        "tensor {name} has {} bytes, its shape needs {expected}",
                        b.len()
                    ));
                    return Err(std::io::Error::other("bad tensor"));
                }
                Err(message) => {
                    failure = Some(format!("tensor {name}: {message}"));
                    return Err(std::io::Error::other("bad tensor"));
                }
            };
            crc.update(&bytes);
            w.write_all(&bytes)?;
        }
        w.seek(SeekFrom::Start(at as u64))?;
        w.write_all(format!("{:08x}", crc.finalize()).as_bytes())?;
        w.seek(SeekFrom::End(0))?;
        Ok(())
    });
    match (written, failure) {
        (_, Some(message)) => Err(bad(message)),
        (result, None) => result,
    }
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// The `format` entry of a safetensors file's metadata, if it has one (files written before
/// the convention may have none at all).
pub fn format_of(bytes: &[u8]) -> Option<String> {
    let (_, header) = SafeTensors::read_metadata(bytes).ok()?;
    header.metadata().as_ref()?.get("format").cloned()
}

/// A file read by [`read_stamped`]: its metadata (the convention's entries included), the
/// version it was written with, and its tensors.
pub struct StampedFile<'a> {
    pub metadata: BTreeMap<String, String>,
    pub version: u32,
    pub tensors: SafeTensors<'a>,
}

/// Reads `bytes` (the whole file at `path`) as a file of `stamp.format`, checking the layout,
/// that the version is not newer than `stamp.version` and the checksum. Files written before
/// the convention (no `version` entry, or a `format` of `<format>/<version>`) read as
/// version 1; a file without a `checksum` entry is accepted only at version 1.
pub fn read_stamped<'a>(bytes: &'a [u8], path: &Path, stamp: Stamp) -> Result<StampedFile<'a>> {
    let bad = |message: String| MeshIoError::Tensors {
        path: path.into(),
        message,
    };
    let (header_len, header) = SafeTensors::read_metadata(bytes)
        .map_err(|e| bad(format!("not a safetensors file: {e}")))?;
    let metadata: BTreeMap<String, String> = header
        .metadata()
        .clone()
        .unwrap_or_default()
        .into_iter()
        .collect();
    let format = metadata.get("format").map(String::as_str).unwrap_or("");
    let (name, legacy_version) = match format.split_once('/') {
        Some((name, v)) => (name, v.parse::<u32>().ok()),
        None => (format, None),
    };
    if name != stamp.format {
        return Err(bad(format!(
            "not a {} file (its metadata says format {format:?})",
            stamp.format
        )));
    }
    let version = match (metadata.get("version"), legacy_version) {
        (Some(v), _) => v
            .parse::<u32>()
            .map_err(|_| bad(format!("unreadable version {v:?}")))?,
        (None, v) => v.unwrap_or(1),
    };
    if version > stamp.version || version == 0 {
        return Err(bad(format!(
            "{} version {version}, this build reads up to {} (written by {}): update meshvae",
            stamp.format,
            stamp.version,
            metadata
                .get("writer")
                .map(String::as_str)
                .unwrap_or("an unknown tool")
        )));
    }
    let data = &bytes[8 + header_len..];
    match metadata.get("checksum") {
        Some(stored) => {
            let actual = format!("crc32:{:08x}", crc32fast::hash(data));
            if *stored != actual {
                return Err(bad(format!(
                    "damaged: the tensor data's checksum is {actual}, the file says {stored} \
                     (rewrite or re-create it)"
                )));
            }
        }
        None if version > 1 => return Err(bad("no checksum in the metadata".into())),
        None => {}
    }
    let tensors = SafeTensors::deserialize(bytes).map_err(|e| bad(e.to_string()))?;
    Ok(StampedFile {
        metadata,
        version,
        tensors,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const STAMP: Stamp = Stamp {
        format: "test-file",
        version: 2,
    };

    fn temp(name: &str) -> crate::scratch::ScratchFile {
        crate::scratch::ScratchFile::new("mesh-io-stamped", name).unwrap()
    }

    fn sample(path: &Path) {
        let a: Vec<f32> = (0..30).map(|i| i as f32 * 0.5).collect();
        write_stamped(
            path,
            STAMP,
            [("k".to_string(), "v".to_string())].into(),
            vec![
                Entry::new("a", Dtype::F32, vec![10, 3], f32_bytes(&a)),
                Entry::lazy("b", Dtype::U32, vec![2], || Ok(u32_bytes(&[7, 9]).into())),
            ],
        )
        .unwrap();
    }

    #[test]
    fn round_trip_keeps_tensors_metadata_and_the_convention() {
        let path = temp("round.safetensors");
        sample(&path);
        let bytes = std::fs::read(&path).unwrap();
        let file = read_stamped(&bytes, &path, STAMP).unwrap();
        assert_eq!(file.version, 2);
        assert_eq!(file.metadata["k"], "v");
        assert_eq!(file.metadata["format"], "test-file");
        assert_eq!(file.metadata["writer"], WRITER);
        let (n, _) = SafeTensors::read_metadata(&bytes).unwrap();
        let expected = format!("crc32:{:08x}", crc32fast::hash(&bytes[8 + n..]));
        assert_eq!(file.metadata["checksum"], expected);
        let a = file.tensors.tensor("a").unwrap();
        assert_eq!(a.shape(), &[10, 3]);
        assert_eq!(&a.data()[4..8], &0.5f32.to_le_bytes());
        assert_eq!(
            file.tensors.tensor("b").unwrap().data(),
            &u32_bytes(&[7, 9])[..]
        );
        // Any reader of the format reads it too.
        assert_eq!(SafeTensors::deserialize(&bytes).unwrap().len(), 2);
    }

    #[test]
    fn one_flipped_data_byte_is_refused_naming_the_file() {
        let path = temp("flip.safetensors");
        sample(&path);
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 13;
        bytes[last] ^= 0x10;
        let err = read_stamped(&bytes, &path, STAMP)
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("flip.safetensors") && err.contains("checksum"),
            "{err}"
        );
    }

    #[test]
    fn foreign_newer_and_unchecked_files_are_refused() {
        let path = temp("other.safetensors");
        sample(&path);
        let bytes = std::fs::read(&path).unwrap();
        let other = Stamp {
            format: "other",
            version: 2,
        };
        let err = read_stamped(&bytes, &path, other)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("not a other file"), "{err}");
        let older = Stamp {
            format: "test-file",
            version: 1,
        };
        let err = read_stamped(&bytes, &path, older)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("version 2") && err.contains("update"), "{err}");
        // A version-2 file without its checksum is not trusted; a version-1 file is read.
        let plain = |meta: HashMapMeta| {
            let view =
                safetensors::tensor::TensorView::new(Dtype::U32, vec![1], &[1, 0, 0, 0]).unwrap();
            safetensors::serialize([("x", view)], Some(meta)).unwrap()
        };
        let v2 = plain(
            [
                ("format".into(), "test-file".into()),
                ("version".into(), "2".into()),
            ]
            .into(),
        );
        assert!(read_stamped(&v2, &path, STAMP).is_err());
        let v1 = plain([("format".into(), "test-file/1".into())].into());
        assert_eq!(read_stamped(&v1, &path, STAMP).unwrap().version, 1);
    }

    type HashMapMeta = std::collections::HashMap<String, String>;

    #[test]
    fn a_tensor_of_the_wrong_size_writes_nothing() {
        let path = temp("short.safetensors");
        let err = write_stamped(
            &path,
            STAMP,
            BTreeMap::new(),
            vec![Entry::new("a", Dtype::F32, vec![3], f32_bytes(&[1.0, 2.0]))],
        )
        .err()
        .unwrap()
        .to_string();
        assert!(err.contains("tensor a has 8 bytes"), "{err}");
        assert!(!path.exists());
    }
}
