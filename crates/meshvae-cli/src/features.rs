//! `meshvae features <SET> --out FILE` and `meshvae roundtrip <SET> [--json]`

use crate::{CliError, print_warnings};
use deform_features::{
    FeatureExtractor, FeatureFile, FeatureOptions, Features, Normalization, RestMesh, save_features,
};
use mesh_io::MeshSet;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options shared by both commands: how features are computed.
#[derive(clap::Args, Clone)]
pub struct FeatureFlags {
    /// The rest mesh: a frame name or index (default: frame 0).
    #[arg(long)]
    rest: Option<String>,
    /// Plain per-vertex fit, without the correction that makes features exactly integrable.
    #[arg(long)]
    plain: bool,
    /// Store principal rotation vectors (|ω| ≤ π) instead of ACAP-consistent ones.
    #[arg(long)]
    principal: bool,
    /// Weight of the vertex-normal pair in the fit, relative to an average ring edge.
    #[arg(long, default_value_t = 1.0)]
    normal_weight: f64,
}

impl FeatureFlags {
    pub fn options(&self) -> FeatureOptions {
        FeatureOptions {
            normal_weight: self.normal_weight,
            consistent_rotations: !self.principal,
            integrable: !self.plain,
        }
    }

    pub fn rest_index(&self, set: &MeshSet) -> Result<usize, CliError> {
        match &self.rest {
            Some(name) => set.find(name).ok_or_else(|| {
                CliError::argument(
                    "--rest",
                    format!("no frame {name:?} (the set has {} frames)", set.len()),
                )
            }),
            None => Ok(0),
        }
    }
}

#[derive(clap::Args)]
pub struct FeaturesArgs {
    /// A folder of mesh files, a multi-frame .glb/.gltf, or a .mvset cache.
    set: PathBuf,
    /// The safetensors file to write.
    #[arg(long)]
    out: PathBuf,
    /// Store raw features instead of normalised ones (the normalisation is stored either way).
    #[arg(long)]
    raw: bool,
    #[command(flatten)]
    flags: FeatureFlags,
}

fn extractor_for(set: &MeshSet, flags: &FeatureFlags) -> Result<FeatureExtractor, CliError> {
    let rest = RestMesh::new(set.frame(flags.rest_index(set)?), set.faces())?;
    Ok(FeatureExtractor::new(rest, flags.options())?)
}

/// The set at `path`, its extractor, the features and the seconds they took; warnings printed.
pub fn load_and_extract(
    path: &Path,
    flags: &FeatureFlags,
) -> Result<(MeshSet, FeatureExtractor, Features, f64), CliError> {
    let loaded = mesh_io::load_set(path)?;
    print_warnings(&loaded.warnings);
    let set = loaded.value;
    let start = Instant::now();
    let extractor = extractor_for(&set, flags)?;
    let out = extractor.extract(&set)?;
    let seconds = start.elapsed().as_secs_f64();
    for w in &out.warnings {
        eprintln!("warning: {w}");
    }
    Ok((set, extractor, out, seconds))
}

pub fn run_features(args: &FeaturesArgs) -> Result<(), CliError> {
    let (set, _, out, seconds) = load_and_extract(&args.set, &args.flags)?;
    let normalization = Normalization::fit([&out.features])?;
    let features = if args.raw {
        out.features
    } else {
        normalization.apply(&out.features)
    };
    let rest_frame = args.flags.rest_index(&set)?;
    let options = serde_json::to_string(&args.flags.options())
        .map_err(|e| CliError::argument("options", e.to_string()))?;
    let file = FeatureFile {
        features,
        normalized: !args.raw,
        normalization: Some(normalization),
        names: set.names().to_vec(),
        rest_positions: Some(set.frame(rest_frame).to_vec()),
        faces: Some(set.faces().to_vec()),
        extra: HashMap::from([
            ("options".to_string(), options),
            ("rest_frame".to_string(), set.names()[rest_frame].clone()),
        ]),
    };
    save_features(&args.out, &file)?;
    out!(
        "{}: {} frames × {} vertices × 9 features in {seconds:.3} s → {}",
        args.set.display(),
        set.len(),
        set.vertex_count(),
        args.out.display()
    );
    out!(
        "  rotation range [{:.6}, {:.6}], stretch range [{:.6}, {:.6}]{}",
        normalization.rotation_min,
        normalization.rotation_max,
        normalization.scale_min,
        normalization.scale_max,
        if args.raw {
            " (stored raw)"
        } else {
            " (stored normalised to ±0.95)"
        }
    );
    Ok(())
}
