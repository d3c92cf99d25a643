//! Builds a hierarchy of a data set's template and reports sizes and timings.
//!
//! `cargo run --release -p mesh-hierarchy --example build_hierarchy -- <set> <pooler> <levels>`

use mesh_hierarchy::{Hierarchy, HierarchyConfig, Pooler};
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
    let path = std::env::temp_dir().join(format!("{set}-{pooler}.hierarchy.json"));
    let t = Instant::now();
    h.save(&path)?;
    let save = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let back = Hierarchy::load(&path)?;
    let load = t.elapsed().as_secs_f64();
    let bytes = std::fs::metadata(&path)?.len();
    std::fs::remove_file(&path)?;
    println!(
        "{set} {pooler} levels {:?}: build {build:.2} s, save {save:.2} s, load {load:.2} s, \
         file {:.1} MB",
        back.vertex_counts(),
        bytes as f64 / 1e6
    );
    Ok(())
}
