//! `meshvae pack SET… --out FILE.mvset|FILE.glb|DIR [--label-names a,b]`
//!
//! One set is written as it is. Several sets of one connectivity become one labelled set: each
//! mesh labelled by its set (the set's folder or file name, or `--label-names`) and named
//! `<label>_<name>`, so that e.g. horse-gallop and horse-poses make one set for a conditional
//! VAE.

use crate::{CliError, print_warnings};
use mesh_io::MeshSet;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct PackArgs {
    /// Mesh sets: folders of mesh files, multi-frame .glb/.gltf files or .mvset caches. Several
    /// sets must share one connectivity.
    #[arg(required = true)]
    sets: Vec<PathBuf>,
    /// What to write, atomically: `*.mvset` for the binary cache, `*.glb` for one glTF file
    /// holding every frame as a morph target with an animation that plays them, or a folder
    /// (a name without extension) of OBJ files plus labels.csv.
    #[arg(long)]
    out: PathBuf,
    /// The labels of the sets, comma-separated, one per set [default: each set's folder or
    /// file name]. With one set, labels every mesh of it.
    #[arg(long, value_delimiter = ',')]
    label_names: Option<Vec<String>>,
}

/// Where `--out` goes.
#[derive(Clone, Copy)]
enum Target {
    Cache,
    Glb,
    Folder,
}

fn target(out: &Path) -> Result<Target, CliError> {
    let ext = out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("mvset") => Ok(Target::Cache),
        Some("glb") => Ok(Target::Glb),
        None => Ok(Target::Folder),
        Some(_) if out.is_dir() => Ok(Target::Folder),
        Some(_) => Err(CliError::argument(
            "--out",
            format!(
                "{}: expected a .mvset or .glb file name, or a folder",
                out.display()
            ),
        )),
    }
}

/// A set's default label: its folder's name, or its file's name without extension.
fn default_label(path: &Path) -> String {
    let name = if path.is_dir() {
        path.canonicalize()
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
    } else {
        path.file_stem().map(|n| n.to_string_lossy().into_owned())
    };
    name.unwrap_or_else(|| path.display().to_string())
}

/// The labels of the sets: `--label-names`, or their names.
fn set_labels(args: &PackArgs) -> Result<Vec<String>, CliError> {
    let labels = match &args.label_names {
        Some(names) => names.iter().map(|n| n.trim().to_string()).collect(),
        None => args
            .sets
            .iter()
            .map(|p| default_label(p))
            .collect::<Vec<_>>(),
    };
    if labels.len() != args.sets.len() {
        return Err(CliError::argument(
            "--label-names",
            format!(
                "{} labels for {} sets: give one per set",
                labels.len(),
                args.sets.len()
            ),
        ));
    }
    if let Some(bad) = labels
        .iter()
        .find(|l| l.is_empty() || l.contains([',', '\n', '\r', '/', '\\']))
    {
        return Err(CliError::argument(
            "--label-names",
            format!("{bad:?} is not a usable label (empty, or with a comma or slash)"),
        ));
    }
    Ok(labels)
}

/// The sets joined into one, each mesh labelled by its set and named `<label>_<name>`.
///
/// Errors: a set of another connectivity than the first (naming it), repeated mesh names.
fn join(sets: &[(PathBuf, MeshSet)], labels: &[String]) -> Result<MeshSet, CliError> {
    let (first_path, first) = &sets[0];
    let template = first.template();
    let mut positions = Vec::new();
    let (mut names, mut mesh_labels) = (Vec::new(), Vec::new());
    for ((path, set), label) in sets.iter().zip(labels) {
        mesh_io::check_same_connectivity(&template, first_path, &set.template(), path)?;
        positions.extend_from_slice(set.positions());
        names.extend(set.names().iter().map(|n| format!("{label}_{n}")));
        mesh_labels.extend(std::iter::repeat_n(label.clone(), set.len()));
    }
    let mut sorted = names.clone();
    sorted.sort();
    if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
        return Err(CliError::argument(
            "--label-names",
            format!(
                "two meshes would be called {:?}: give the sets distinct labels",
                w[0]
            ),
        ));
    }
    let joined = MeshSet::from_flat(
        first.faces().to_vec(),
        first.vertex_count(),
        positions,
        names,
    )?;
    Ok(joined.with_labels(mesh_labels)?)
}

pub fn run(args: &PackArgs) -> Result<(), CliError> {
    let target = target(&args.out)?;
    let labels = match (&args.label_names, args.sets.len()) {
        (None, 1) => None,
        _ => Some(set_labels(args)?),
    };
    if let Target::Folder = target {
        let non_empty = std::fs::read_dir(&args.out).is_ok_and(|mut d| d.next().is_some());
        if non_empty || args.out.is_file() {
            return Err(CliError::argument(
                "--out",
                format!("{} exists and is not an empty folder", args.out.display()),
            ));
        }
    }
    let mut sets = Vec::with_capacity(args.sets.len());
    for path in &args.sets {
        let loaded = mesh_io::load_set(path)?;
        print_warnings(&loaded.warnings);
        sets.push((path.clone(), loaded.value));
    }
    let set = match &labels {
        None => sets.swap_remove(0).1,
        Some(labels) if sets.len() == 1 => {
            let set = sets.swap_remove(0).1;
            let n = set.len();
            set.with_labels(vec![labels[0].clone(); n])?
        }
        Some(labels) => join(&sets, labels)?,
    };
    match target {
        Target::Cache => mesh_io::cache::write_cache(&args.out, &set)?,
        Target::Glb => {
            if labels.is_some() {
                eprintln!("warning: a .glb file keeps no labels; write .mvset or a folder");
            }
            mesh_io::glb::write_glb_set(&args.out, &set)?
        }
        Target::Folder => {
            mesh_io::write_folder(&args.out, &set)?;
        }
    }
    let labelled = match set.distinct_labels() {
        Some(l) if labels.is_some() => format!(", labelled {}", l.join(", ")),
        _ => String::new(),
    };
    eprintln!(
        "wrote {} ({} meshes of {} vertices{labelled})",
        args.out.display(),
        set.len(),
        set.vertex_count()
    );
    Ok(())
}
