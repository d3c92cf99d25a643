//! Version 2: the stamped safetensors layout described in the parent module.

use super::{FORMAT, VERSION};
use crate::error::HierarchyError;
use crate::hierarchy::{Hierarchy, HierarchyConfig, Level};
use crate::pooling::{Pooler, PoolingOp};
use mesh_io::MeshIoError;
use mesh_io::stamped::{
    Dtype, Entry, Stamp, StampedFile, f32_bytes, f64_bytes, read_stamped, write_stamped,
};
use serde::{Deserialize, Serialize};
use sparse_csr::CsrMatrix;
use std::path::Path;

const STAMP: Stamp = Stamp {
    format: FORMAT,
    version: VERSION,
};

/// The metadata entry holding the [`Outline`].
const OUTLINE: &str = "hierarchy";

/// Everything of a hierarchy but its arrays.
#[derive(Serialize, Deserialize)]
struct Outline {
    config: HierarchyConfig,
    levels: Vec<LevelOutline>,
    pooling: Vec<StepOutline>,
}

#[derive(Serialize, Deserialize)]
struct LevelOutline {
    vertex_count: usize,
    laplacian: Size,
}

#[derive(Serialize, Deserialize)]
struct StepOutline {
    kind: Pooler,
    pool: Size,
    depool: Size,
    /// Whether `pooling.i.clusters.*` exist.
    clusters: bool,
}

/// A sparse matrix's shape (the column count is not in its arrays).
#[derive(Serialize, Deserialize, Clone, Copy)]
struct Size {
    rows: usize,
    cols: usize,
}

impl Size {
    fn of(m: &CsrMatrix) -> Self {
        Self {
            rows: m.rows(),
            cols: m.cols(),
        }
    }
}

pub(super) fn write(h: &Hierarchy, path: &Path) -> Result<(), HierarchyError> {
    let outline = Outline {
        config: h.config,
        levels: h
            .levels
            .iter()
            .map(|l| LevelOutline {
                vertex_count: l.vertex_count,
                laplacian: Size::of(&l.laplacian),
            })
            .collect(),
        pooling: h
            .pooling
            .iter()
            .map(|op| StepOutline {
                kind: op.kind,
                pool: Size::of(&op.pool),
                depool: Size::of(&op.depool),
                clusters: op.clusters.is_some(),
            })
            .collect(),
    };
    let outline =
        serde_json::to_string(&outline).map_err(|e| HierarchyError::file(path, e.to_string()))?;
    // Lazy entries: each array becomes bytes only when written, so the file never exists
    // twice in memory.
    let mut entries = Vec::new();
    for (i, level) in h.levels.iter().enumerate() {
        let (faces, positions) = (level.faces.as_flattened(), level.positions.as_flattened());
        entries.push(uints(
            format!("level.{i}.faces"),
            vec![level.faces.len(), 3],
            move || faces.iter().map(|&v| u64::from(v)),
        ));
        entries.push(Entry::lazy(
            format!("level.{i}.positions"),
            Dtype::F32,
            vec![level.positions.len(), 3],
            move || Ok(f32_bytes(positions).into()),
        ));
        push_csr(
            &mut entries,
            format!("level.{i}.laplacian"),
            &level.laplacian,
        );
    }
    for (i, op) in h.pooling.iter().enumerate() {
        push_csr(&mut entries, format!("pooling.{i}.pool"), &op.pool);
        push_csr(&mut entries, format!("pooling.{i}.depool"), &op.depool);
        if let Some(clusters) = &op.clusters {
            let ends = move || {
                let ends = clusters.iter().scan(0, |end, c| {
                    *end += c.len() as u64;
                    Some(*end)
                });
                std::iter::once(0).chain(ends)
            };
            entries.push(uints(
                format!("pooling.{i}.clusters.offsets"),
                vec![clusters.len() + 1],
                ends,
            ));
            entries.push(uints(
                format!("pooling.{i}.clusters.members"),
                vec![clusters.iter().map(Vec::len).sum()],
                move || clusters.iter().flatten().map(|&v| u64::from(v)),
            ));
        }
    }
    write_stamped(path, STAMP, [(OUTLINE.into(), outline)].into(), entries)?;
    Ok(())
}

/// The three arrays of `m` as `<name>.indptr`, `<name>.indices` and `<name>.values`.
fn push_csr<'a>(entries: &mut Vec<Entry<'a>>, name: String, m: &'a CsrMatrix) {
    entries.push(uints(
        format!("{name}.indptr"),
        vec![m.indptr().len()],
        || m.indptr().iter().map(|&v| v as u64),
    ));
    entries.push(uints(format!("{name}.indices"), vec![m.nnz()], || {
        m.indices().iter().map(|&v| u64::from(v))
    }));
    entries.push(Entry::lazy(
        format!("{name}.values"),
        Dtype::F64,
        vec![m.nnz()],
        || Ok(f64_bytes(m.values()).into()),
    ));
}

/// An unsigned integer array in the narrowest of U16, U32 and U64 that holds its largest
/// value: lossless, and the index arrays of a mesh under 65,536 vertices take half the room of
/// U32. `values` is called twice, for the largest value and for the bytes.
fn uints<'a, I: Iterator<Item = u64>>(
    name: String,
    shape: Vec<usize>,
    values: impl Fn() -> I + 'a,
) -> Entry<'a> {
    let dtype = match values().max().unwrap_or(0) {
        m if m <= u64::from(u16::MAX) => Dtype::U16,
        m if m <= u64::from(u32::MAX) => Dtype::U32,
        _ => Dtype::U64,
    };
    Entry::lazy(name, dtype, shape, move || {
        let bytes: Vec<u8> = match dtype {
            Dtype::U16 => values().flat_map(|v| (v as u16).to_le_bytes()).collect(),
            Dtype::U32 => values().flat_map(|v| (v as u32).to_le_bytes()).collect(),
            _ => values().flat_map(u64::to_le_bytes).collect(),
        };
        Ok(bytes.into())
    })
}

/// The hierarchy of a version-2 file, not yet checked beyond its sparse matrices.
pub(super) fn read(bytes: &[u8], path: &Path) -> Result<Hierarchy, HierarchyError> {
    let file = read_stamped(bytes, path, STAMP).map_err(|e| match e {
        MeshIoError::Tensors { path, message } => HierarchyError::File { path, message },
        other => other.into(),
    })?;
    let r = Reader { file: &file, path };
    // No safetensors hierarchy of version 1 was ever written (version 1 is JSON).
    if file.version != VERSION {
        return Err(r.bad(format!(
            "a safetensors file of version {}, expected {VERSION}",
            file.version
        )));
    }
    let outline = file
        .metadata
        .get(OUTLINE)
        .ok_or_else(|| r.bad(format!("no {OUTLINE:?} entry in the metadata")))?;
    let outline: Outline =
        serde_json::from_str(outline).map_err(|e| r.bad(format!("metadata {OUTLINE:?}: {e}")))?;
    let levels = outline
        .levels
        .iter()
        .enumerate()
        .map(|(i, l)| {
            Ok(Level {
                vertex_count: l.vertex_count,
                faces: triples(r.uints(&format!("level.{i}.faces"), Some(3))?),
                positions: triples(r.f32s(&format!("level.{i}.positions"), Some(3))?),
                laplacian: r.csr(&format!("level.{i}.laplacian"), l.laplacian)?,
            })
        })
        .collect::<Result<_, HierarchyError>>()?;
    let pooling = outline
        .pooling
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let clusters = if s.clusters {
                Some(r.clusters(&format!("pooling.{i}.clusters"))?)
            } else {
                None
            };
            Ok(PoolingOp {
                kind: s.kind,
                pool: r.csr(&format!("pooling.{i}.pool"), s.pool)?,
                depool: r.csr(&format!("pooling.{i}.depool"), s.depool)?,
                clusters,
            })
        })
        .collect::<Result<_, HierarchyError>>()?;
    Ok(Hierarchy {
        levels,
        pooling,
        config: outline.config,
    })
}

fn triples<T: Copy>(flat: Vec<T>) -> Vec<[T; 3]> {
    flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// Decodes little-endian values of `N` bytes each (`bytes` holds a whole number of them).
fn decode<const N: usize, T>(bytes: &[u8], from: impl Fn([u8; N]) -> T) -> Vec<T> {
    bytes
        .chunks_exact(N)
        .map(|c| {
            let mut word = [0u8; N];
            word.copy_from_slice(c);
            from(word)
        })
        .collect()
}

/// The tensors of one file, each checked for its element type and shape before decoding.
struct Reader<'a, 'data> {
    file: &'a StampedFile<'data>,
    path: &'a Path,
}

impl<'data> Reader<'_, 'data> {
    fn bad(&self, message: String) -> HierarchyError {
        HierarchyError::file(self.path, message)
    }

    /// The element type and bytes of tensor `name`, which must be one of `dtypes`, of shape
    /// [k] (`width` `None`) or [k, width].
    fn raw(
        &self,
        name: &str,
        dtypes: &[Dtype],
        width: Option<usize>,
    ) -> Result<(Dtype, &'data [u8]), HierarchyError> {
        let t = self
            .file
            .tensors
            .tensor(name)
            .map_err(|_| self.bad(format!("tensor {name} is missing")))?;
        let shape_ok = match (t.shape(), width) {
            ([_], None) => true,
            ([_, w], Some(width)) => *w == width,
            _ => false,
        };
        if !dtypes.contains(&t.dtype()) || !shape_ok {
            let expected = match width {
                Some(w) => format!("[k, {w}]"),
                None => "[k]".into(),
            };
            return Err(self.bad(format!(
                "tensor {name} is {:?} {:?}, expected {} {expected}",
                t.dtype(),
                t.shape(),
                dtypes
                    .iter()
                    .map(|d| format!("{d:?}"))
                    .collect::<Vec<_>>()
                    .join(" or ")
            )));
        }
        Ok((t.dtype(), t.data()))
    }

    /// An unsigned integer array of any of the widths written, whose values must fit `T`.
    fn uints<T: TryFrom<u64>>(
        &self,
        name: &str,
        width: Option<usize>,
    ) -> Result<Vec<T>, HierarchyError> {
        let (dtype, bytes) = self.raw(name, &[Dtype::U16, Dtype::U32, Dtype::U64], width)?;
        let values = match dtype {
            Dtype::U16 => decode(bytes, |b| u64::from(u16::from_le_bytes(b))),
            Dtype::U32 => decode(bytes, |b| u64::from(u32::from_le_bytes(b))),
            _ => decode(bytes, u64::from_le_bytes),
        };
        values
            .into_iter()
            .map(|v| {
                T::try_from(v).map_err(|_| self.bad(format!("tensor {name}: {v} is too large")))
            })
            .collect()
    }

    fn f32s(&self, name: &str, width: Option<usize>) -> Result<Vec<f32>, HierarchyError> {
        let (_, bytes) = self.raw(name, &[Dtype::F32], width)?;
        Ok(decode(bytes, f32::from_le_bytes))
    }

    fn f64s(&self, name: &str) -> Result<Vec<f64>, HierarchyError> {
        let (_, bytes) = self.raw(name, &[Dtype::F64], None)?;
        Ok(decode(bytes, f64::from_le_bytes))
    }

    fn csr(&self, name: &str, size: Size) -> Result<CsrMatrix, HierarchyError> {
        CsrMatrix::new(
            size.rows,
            size.cols,
            self.uints(&format!("{name}.indptr"), None)?,
            self.uints(&format!("{name}.indices"), None)?,
            self.f64s(&format!("{name}.values"))?,
        )
        .map_err(|e| self.bad(format!("{name}: {e}")))
    }

    fn clusters(&self, name: &str) -> Result<Vec<Vec<u32>>, HierarchyError> {
        let offsets: Vec<usize> = self.uints(&format!("{name}.offsets"), None)?;
        let members: Vec<u32> = self.uints(&format!("{name}.members"), None)?;
        let ok = offsets.first() == Some(&0)
            && offsets.last() == Some(&members.len())
            && offsets.windows(2).all(|w| w[0] <= w[1]);
        if !ok {
            return Err(self.bad(format!(
                "{name}.offsets do not split {} members",
                members.len()
            )));
        }
        Ok(offsets
            .windows(2)
            .map(|w| members[w[0]..w[1]].to_vec())
            .collect())
    }
}
