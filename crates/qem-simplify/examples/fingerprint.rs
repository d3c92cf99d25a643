//! A hash of the whole result (map, survivors, coarse positions' bits, faces, face origins) per
//! template and λ, to check that a change to the simplifier's internals keeps its output:
//! `cargo run --release -p qem-simplify --example fingerprint [-- SET...]`.

use qem_simplify::{SimplifyConfig, Target, simplify};
use std::hash::{DefaultHasher, Hash, Hasher};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut names: Vec<String> = std::env::args().skip(1).collect();
    if names.is_empty() {
        names = ["horse-gallop", "samba", "elephant-gallop"]
            .map(String::from)
            .to_vec();
    }
    for name in &names {
        let Some(dir) = mesh_io::datasets::find(name) else {
            eprintln!("{name}: not found, skipped");
            continue;
        };
        let fine = mesh_io::load_set(&dir)?.value.template();
        for lambda in [0.0, 1e-4, 0.001, 0.01] {
            let config = SimplifyConfig {
                target: Target::Ratio(0.5),
                lambda,
            };
            let s = simplify(&fine, &config)?;
            let mut h = DefaultHasher::new();
            s.cluster_of.hash(&mut h);
            s.survivors.hash(&mut h);
            s.face_origin.hash(&mut h);
            s.coarse.faces.hash(&mut h);
            for p in &s.coarse.positions {
                p.map(f32::to_bits).hash(&mut h);
            }
            println!("{name} lambda={lambda:e}: {:016x}", h.finish());
        }
    }
    Ok(())
}
