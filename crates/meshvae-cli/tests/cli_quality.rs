//! A model that has learned nothing is not reported as a success: `eval`, `reconstruct`,
//! `generate` and `interpolate` warn, on the terminal and in their JSON, on a one-epoch
//! horse-gallop model.

mod common;

use common::{meshvae, ok, s, scratch};

#[test]
fn a_one_epoch_horse_model_is_flagged_by_every_command_that_uses_it() {
    let Some(horse) = mesh_io::datasets::find_or_skip("horse-gallop") else {
        return;
    };
    let dir = scratch("quality");
    let model = dir.join("model");
    ok(&meshvae(&[
        "train",
        s(&horse),
        "--out",
        s(&model),
        "--epochs",
        "1",
        "--quiet",
    ]));

    let out = meshvae(&["eval", s(&model), "--json"]);
    let report: serde_json::Value = serde_json::from_str(&ok(&out)).unwrap();
    let kinds: Vec<&str> = report["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["kind"].as_str().unwrap())
        .collect();
    assert!(kinds.contains(&"no_better_than_mean_shape"), "{report}");
    let (test, mean) = (
        report["test_rms"].as_f64().unwrap(),
        report["mean_shape_rms"].as_f64().unwrap(),
    );
    assert!(test > 0.5 * mean, "test {test}, mean shape {mean}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("warning: the test error") && stderr.contains("--resume"),
        "{stderr}"
    );

    let generated = dir.join("gen");
    let out = meshvae(&["generate", s(&model), "-n", "1", "--out", s(&generated)]);
    ok(&out);
    assert!(String::from_utf8_lossy(&out.stderr).contains("warning: the test error"));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(generated.join("report.json")).unwrap())
            .unwrap();
    assert_eq!(
        report["warnings"][0]["kind"], "no_better_than_mean_shape",
        "{report}"
    );

    let out = meshvae(&[
        "interpolate",
        s(&model),
        "--from",
        "0",
        "--to",
        "5",
        "--steps",
        "2",
        "--out",
        s(&dir.join("int")),
    ]);
    ok(&out);
    assert!(String::from_utf8_lossy(&out.stderr).contains("warning: the test error"));

    let out = meshvae(&["reconstruct", s(&model), "--out", s(&dir.join("rec"))]);
    ok(&out);
    assert!(String::from_utf8_lossy(&out.stderr).contains("warning: the test error"));
}
