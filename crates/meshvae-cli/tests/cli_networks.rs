//! `meshvae train --net`: the other auto-encoders train, evaluate, reconstruct and resume as ours
//! does, and the flags that shape our network alone are refused with them.

mod common;
use common::*;

#[test]
fn every_network_trains_evaluates_reconstructs_and_resumes() {
    // 2,498 vertices: enough for four samplings by 4.
    let (dir, set, _) = synth_case("networks", 4);
    for (net, channels) in [("tan2018", 9), ("coma", 3), ("spiralnet", 3)] {
        let model = dir.join(net);
        let out = ok(&train_short(&set, &model, 2, &["--net", net]));
        assert!(out.contains("candle"), "{net}: {out}");
        let config = std::fs::read_to_string(model.join("config.json")).unwrap();
        assert!(config.contains(&format!("\"net\": \"{net}\"")), "{config}");
        let scaling = std::fs::read_to_string(model.join("normalization.json")).unwrap();
        assert_eq!(scaling.contains("position_mean"), channels == 3, "{net}");

        let report = ok(&meshvae(&["eval", s(&model), "--json"]));
        let json: serde_json::Value = serde_json::from_str(&report).unwrap();
        assert_eq!(json["net"], net);
        let rms = json["test_rms"].as_f64().unwrap();
        let mean_shape = json["mean_shape_rms"].as_f64().unwrap();
        assert!(
            rms.is_finite() && rms > 0.0 && mean_shape > 0.0,
            "{net}: {report}"
        );
        assert!(json["params"].as_u64().unwrap() > 0);

        let meshes = dir.join(format!("{net}-meshes"));
        ok(&meshvae(&[
            "reconstruct",
            s(&model),
            "--set",
            s(&set),
            "--out",
            s(&meshes),
        ]));
        let objs = std::fs::read_dir(&meshes).unwrap().count();
        assert!(objs > 0, "{net}: no reconstruction written");

        let resumed = train_short(&set, &model, 3, &["--resume"]);
        ok(&resumed);
        let log = std::fs::read_to_string(model.join("log.jsonl")).unwrap();
        assert_eq!(log.lines().count(), 3, "{net}: {log}");
    }
    // A resumed run may not change the network.
    let resumed = train_short(
        &set,
        &dir.join("coma"),
        4,
        &["--resume", "--net", "spiralnet"],
    );
    fails_with(&resumed, 1, "model");
}

#[test]
fn flags_of_our_network_are_refused_with_another_and_small_meshes_are_explained() {
    let (dir, set, model) = synth_case("networks-flags", 2);
    for flag in [&["--k", "4"][..], &["--pool", "qem"], &["--conditional"]] {
        let mut args = vec!["--net", "coma"];
        args.extend_from_slice(flag);
        fails_with(&train_short(&set, &model, 1, &args), 1, flag[0]);
    }
    fails_with(
        &train_short(&set, &model, 1, &["--net", "pointnet"]),
        2,
        "spiralnet",
    );
    assert!(!model.join("config.json").exists());
    // 722 vertices cannot be sampled down by 4 four times.
    let small = dir.join("small");
    ok(&meshvae(&[
        "synth",
        "--out",
        s(&small),
        "--per-label",
        "2",
        "--rings",
        "24",
        "--segments",
        "24",
        "--cap-rings",
        "3",
    ]));
    let out = train_short(&small, &model, 1, &["--net", "spiralnet"]);
    fails_with(&out, 1, "at least 1024 vertices");
}
