//! `meshvae interpolate`: the latent path between two meshes of the set, as OBJ files, one GLB
//! that plays the sequence (morph-target animation) and a PNG strip.

use crate::CliError;
use crate::generate::{
    check_quality, create_out, model_and_set, tiles, to_mesh, write_json, write_png,
};
use mesh_io::{MeshSet, TriMesh};
use mesh_render::View;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct InterpolateArgs {
    /// A model folder written by `meshvae train`.
    model: PathBuf,
    /// The first mesh: its name in the set or its index.
    #[arg(long)]
    from: String,
    /// The last mesh: its name in the set or its index.
    #[arg(long)]
    to: String,
    /// Meshes in the sequence, both ends included (at least 2).
    #[arg(long, default_value_t = 10)]
    steps: usize,
    /// Folder for step_00.obj, …, interpolation.glb, strip.png and interpolation.json.
    #[arg(long)]
    out: PathBuf,
    /// The mesh set (default: the one recorded in the model's config).
    #[arg(long)]
    set: Option<PathBuf>,
    /// The side the strip looks from: auto (along the thinnest axis of the box, y up where
    /// possible), front, back, left, right, top or bottom.
    #[arg(long, default_value = "auto")]
    view: View,
}

pub fn run(args: &InterpolateArgs) -> Result<(), CliError> {
    if args.steps < 2 {
        return Err(CliError::argument(
            "--steps",
            format!("{}: at least 2 (both ends are included)", args.steps),
        ));
    }
    let (trained, set) = model_and_set(&args.model, args.set.as_ref())?;
    let warnings = check_quality(&trained, &set, &args.model)?;
    let seq = meshvae::interpolate(&trained, &set, &args.from, &args.to, args.steps).map_err(
        |e| match e {
            // The library names its arguments `from` / `to`; the user typed the flags.
            meshvae::VaeError::Argument { arg, what } if arg == "from" || arg == "to" => {
                CliError::argument(if arg == "from" { "--from" } else { "--to" }, what)
            }
            other => other.into(),
        },
    )?;
    let meshes: Vec<TriMesh> = seq
        .positions
        .iter()
        .map(|p| to_mesh(p, set.faces()))
        .collect::<Result<_, _>>()?;
    let digits = (args.steps - 1).to_string().len().max(2);
    let names: Vec<String> = (0..args.steps)
        .map(|i| format!("step_{i:0digits$}"))
        .collect();
    let (from_name, to_name) = (&set.names()[seq.from], &set.names()[seq.to]);

    // Everything that can fail on content comes before the first write.
    let animation = MeshSet::from_meshes(meshes.clone(), names.clone())?;
    let captioned: Vec<(&[[f32; 3]], String)> = meshes
        .iter()
        .zip(&seq.t)
        .enumerate()
        .map(|(i, (m, t))| {
            let caption = if i == 0 {
                from_name.clone()
            } else if i + 1 == meshes.len() {
                to_name.clone()
            } else {
                format!("t = {t:.2}")
            };
            (m.positions.as_slice(), caption)
        })
        .collect();
    let view = args.view.for_set(set.frame(0));
    let strip = mesh_render::sheet(&tiles(&captioned, set.faces(), view)?, args.steps)?;

    create_out(&args.out)?;
    for (mesh, name) in meshes.iter().zip(&names) {
        mesh_io::write_mesh(&args.out.join(format!("{name}.obj")), mesh)?;
    }
    mesh_io::glb::write_glb_set(&args.out.join("interpolation.glb"), &animation)?;
    write_png(&args.out.join("strip.png"), &strip)?;
    write_json(
        &args.out.join("interpolation.json"),
        &serde_json::json!({
            "model": args.model,
            "from": from_name,
            "from_index": seq.from,
            "to": to_name,
            "to_index": seq.to,
            "t": seq.t,
            "files": names.iter().map(|n| format!("{n}.obj")).collect::<Vec<_>>(),
            "latents": seq.latents,
            "warnings": warnings,
        }),
    )?;
    out!(
        "wrote {} meshes from {from_name} to {to_name}, interpolation.glb, strip.png and \
         interpolation.json to {}",
        args.steps,
        args.out.display()
    );
    Ok(())
}
