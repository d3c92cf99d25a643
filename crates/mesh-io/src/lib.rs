//! # mesh-io: read, validate, write and cache sets of triangle meshes
//!
//! **In:** mesh files (OBJ, OFF, PLY, glTF/GLB) — a folder of them, a list, or one GLB whose
//! morph targets are the frames — all sharing one connectivity, plus an optional labels CSV.
//! **Out:** a validated [`MeshSet`] (one face list, N frames of positions, names, labels), a
//! [`QualityReport`], OBJ/GLB files, a one-file binary cache (`.mvset`) that loads an order of
//! magnitude faster than the OBJ files it came from, and [`ShapeGroups`]: which meshes of a set
//! are one shape (an animation cycle stored twice), for splits that keep such twins together.
//! [`stamped`] holds the metadata convention (format, version, writer, CRC-32 checksum) of
//! every safetensors file the tool writes, the `.mvset` cache among them; [`scratch`] gives the
//! workspace's tests a file in a temporary folder of its own, removed when dropped.
//!
//! Every problem is a typed [`MeshIoError`] naming the file and what is wrong; nothing panics on
//! bad input, and every writer writes a temporary file and renames it.
//!
//! ```no_run
//! use mesh_io::MeshSet;
//! # fn main() -> Result<(), mesh_io::MeshIoError> {
//! let loaded = mesh_io::load_set("../shared/datasets/horse-gallop".as_ref())?;
//! for warning in &loaded.warnings {
//!     eprintln!("warning: {warning}");
//! }
//! let set: MeshSet = loaded.value;
//! println!("{} meshes of {} vertices", set.len(), set.vertex_count());
//! let report = mesh_io::QualityReport::of(&set);
//! println!("{} boundary edges", report.boundary_edges);
//! mesh_io::cache::write_cache("horse.mvset".as_ref(), &set)?;
//! # Ok(()) }
//! ```
//!
//! Synthetic sets with known parameters (a capsule that bends and twists) come from
//! [`synth`]; they are the project's default data for demos and fast tests.

pub mod atomic;
pub mod cache;
pub mod datasets;
mod error;
pub mod format;
pub mod glb;
pub mod labels;
mod mesh;
pub mod obj;
pub mod off;
pub mod ply;
mod quality;
pub mod scratch;
pub mod set;
pub mod stamped;
pub mod synth;
mod twins;

pub use error::{MeshIoError, Result, Warning};
pub use format::{MeshFormat, read_mesh, write_mesh};
pub use mesh::{Face, MeshSet, Point, TriMesh, bbox, bbox_diagonal, check_same_connectivity};
pub use quality::{OUTLIER_FACTOR, OutlierFrame, QualityReport};
pub use set::{load_files, load_folder, load_set, write_folder};
pub use twins::ShapeGroups;

/// A value read from files, with the warnings met on the way (quads split, …).
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded<T> {
    pub value: T,
    pub warnings: Vec<Warning>,
}

impl<T> Loaded<T> {
    pub fn new(value: T) -> Self {
        Self {
            value,
            warnings: Vec::new(),
        }
    }
}
