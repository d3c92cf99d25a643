//! Builds a hierarchy of a data set's template and reports sizes and timings, of the file and
//! of the version-1 JSON.
//!
//! `cargo run --release -p mesh-hierarchy --example build_hierarchy -- <set> <pooler> <levels>`

use mesh_hierarchy::{Hierarchy, HierarchyConfig, HierarchyError, Pooler};
use std::path::Path;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let set = args.first().map_or("horse-gallop", String::as_str);
    let pooler: Pooler = args.get(1).map_or("ours", String::as_str).parse()?;
    let levels: usize = args.get(2).map_or("2", String::as_str).parse()?;
    let Some(dir) = mesh_io::datasets::find_or_skip(set) else {
        return Ok(());
    };
    let template = mesh_io::load_set(&dir)?.value.template();
    let config = HierarchyConfig {
        pooler,
        levels,
        ..Default::default()
    };
    let t = Instant::now();
    let h = Hierarchy::build(&template, &config)?;
    let build = t.elapsed().as_secs_f64();
    let dir = std::env::temp_dir();
    let binary = dir.join(format!("{set}-{pooler}-{}.hierarchy", std::process::id()));
    let json = dir.join(format!(
        "{set}-{pooler}-{}.hierarchy.json",
        std::process::id()
    ));
    let (save, load, bytes) = timed(&h, &binary, Hierarchy::save)?;
    // The version-1 JSON, for comparison: model folders written before version 2 hold it.
    let (save_json, load_json, bytes_json) = timed(&h, &json, Hierarchy::save_json)?;
    println!(
        "{set} {pooler} levels {:?}: build {build:.2} s; file {:.2} MB, save {save:.3} s, \
         load {load:.3} s; version-1 JSON {:.2} MB, save {save_json:.3} s, load {load_json:.3} s",
        h.vertex_counts(),
        bytes as f64 / 1e6,
        bytes_json as f64 / 1e6
    );
    Ok(())
}

/// Saves `h` to `path` with `save`, loads it back (it must be equal) and removes the file:
/// save and load seconds and the file's size.
fn timed(
    h: &Hierarchy,
    path: &Path,
    save: fn(&Hierarchy, &Path) -> Result<(), HierarchyError>,
) -> Result<(f64, f64, u64), Box<dyn std::error::Error>> {
    let t = Instant::now();
    save(h, path)?;
    let saved = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let back = Hierarchy::load(path)?;
    let loaded = t.elapsed().as_secs_f64();
    let bytes = std::fs::metadata(path)?.len();
    std::fs::remove_file(path)?;
    if back != *h {
        return Err(format!("{} did not load back equal", path.display()).into());
    }
    Ok((saved, loaded, bytes))
}
