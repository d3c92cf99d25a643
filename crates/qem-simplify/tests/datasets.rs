//! Acceptance on the real templates (skipped when the data sets are absent): manifold output,
//! no flips, Euler characteristic kept, exact count, complete map, connected clusters, and the
//! edge-length term making edges more even than classical QEM.

mod common;

use qem_simplify::{SimplifyConfig, Target, UniformityReport, simplify};

fn acceptance(name: &str) {
    let Some(dir) = mesh_io::datasets::find_or_skip(name) else {
        return;
    };
    let set = mesh_io::load_set(&dir).expect("data set loads").value;
    let fine = set.template();
    let target = fine.vertex_count().div_ceil(2);
    let mut cv = Vec::new();
    for lambda in [0.0, 0.001] {
        let config = SimplifyConfig {
            target: Target::Ratio(0.5),
            lambda,
        };
        let s = simplify(&fine, &config).expect("simplifies");
        common::check_simplified(&fine, &s, target);
        let report = UniformityReport::of(&fine, &s);
        eprintln!("{name} lambda={lambda}: {report:?}");
        cv.push(report.edge_cv);
    }
    assert!(
        cv[1] < cv[0],
        "{name}: edge CV {} with lambda, {} without",
        cv[1],
        cv[0]
    );
}

#[test]
fn horse_gallop_template() {
    acceptance("horse-gallop");
}

#[test]
fn samba_template() {
    acceptance("samba");
}

#[test]
fn elephant_gallop_template() {
    acceptance("elephant-gallop");
}
