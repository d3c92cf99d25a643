//! Times `simplify` on one data set's template: `cargo run --release -p qem-simplify --example
//! time -- SET|MESH [LAMBDA] [REPEATS]`.

use qem_simplify::{SimplifyConfig, Target, simplify};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().map_or("elephant-gallop", String::as_str);
    let lambda: f64 = args.get(1).map_or(Ok(0.001), |s| s.parse())?;
    let repeats: usize = args.get(2).map_or(Ok(3), |s| s.parse())?;
    // A data set's name, or a single mesh file.
    let fine = match mesh_io::datasets::find(name) {
        Some(dir) => mesh_io::load_set(&dir)?.value.template(),
        None => mesh_io::read_mesh(name.as_ref())?.value,
    };
    let config = SimplifyConfig {
        target: Target::Ratio(0.5),
        lambda,
    };
    for _ in 0..repeats {
        let start = Instant::now();
        let s = simplify(&fine, &config)?;
        println!(
            "{name}: {} -> {} vertices in {:.3} s",
            fine.vertex_count(),
            s.coarse.vertex_count(),
            start.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
