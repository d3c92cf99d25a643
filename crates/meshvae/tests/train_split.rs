//! The split of a set into training, validation and test meshes: test meshes influence
//! nothing, and copies of one shape stay on one side.

mod common;

use candle_core::Device;
use common::{options, request, scratch, small_set};
use mesh_io::MeshSet;
use meshvae::{
    ModelFolder, Selection, Split, SplitFile, TrainOptions, TrainedModel, read_log, train,
};
use std::path::PathBuf;

/// The default protocol: no test mesh influences training or the choice of checkpoint. Two
/// runs whose sets differ only in the test meshes (bent out of shape) end with bit-identical
/// weights, checkpoints and validation losses; only the logged test losses differ.
#[test]
fn test_meshes_influence_neither_training_nor_the_chosen_checkpoint() {
    let set = small_set(3, 8);
    let out_a = scratch("leak-a");
    let out_b = scratch("leak-b");
    // Every epoch's test loss, to see each one differ.
    let options = |resume, force| TrainOptions {
        test_every_steps: 1,
        ..options(resume, force)
    };
    // Run a keeps the weights chosen on the test loss, b only their epoch: nothing else
    // changes.
    let keep = TrainOptions {
        keep_selected_on_test: true,
        ..options(false, false)
    };
    let a = train(&request(&set, &out_a, 4), &keep, |_| {}).unwrap();
    assert_eq!(a.selected_on, Selection::Validation);
    let split = TrainedModel::load(&out_a, &Device::Cpu).unwrap().split;
    assert!(!split.val.is_empty() && !split.test.is_empty());
    assert!(split.train.contains(&0), "the rest pose trains");

    let mut positions = Vec::new();
    for (i, frame) in set.frames().enumerate() {
        let test = split.test.contains(&i);
        positions.extend(frame.iter().map(|p| match test {
            true => [
                p[0] * 1.3 + 0.2 * p[1] * p[1],
                p[1] * 0.8,
                p[2] + 0.1 * p[0],
            ],
            false => *p,
        }));
    }
    let perturbed = MeshSet::from_flat(
        set.faces().to_vec(),
        set.vertex_count(),
        positions,
        set.names().to_vec(),
    )
    .unwrap();
    train(
        &request(&perturbed, &out_b, 4),
        &options(false, false),
        |_| {},
    )
    .unwrap();

    let (fa, fb) = (ModelFolder::new(&out_a), ModelFolder::new(&out_b));
    let read = |path: PathBuf| std::fs::read(path).unwrap();
    assert!(
        read(fa.weights()) == read(fb.weights()),
        "best weights differ"
    );
    // The checkpoints' training state (weights, batch-norm statistics, Adam's moments) is
    // identical; only their record of the best test loss differs.
    let state = |f: &ModelFolder| {
        let map = candle_core::safetensors::load(f.checkpoint(), &Device::Cpu).unwrap();
        let mut state: Vec<(String, Vec<f64>)> = map
            .into_iter()
            .filter(|(k, _)| k.starts_with("model.") || k.starts_with("adam."))
            .map(|(k, t)| {
                let t = t.flatten_all().unwrap();
                (
                    k,
                    t.to_dtype(candle_core::DType::F64)
                        .unwrap()
                        .to_vec1()
                        .unwrap(),
                )
            })
            .collect();
        state.sort_by(|a, b| a.0.cmp(&b.0));
        state
    };
    let (sa, sb) = (state(&fa), state(&fb));
    assert!(sa.len() > 10, "{} tensors", sa.len());
    for ((ka, a), (kb, b)) in sa.iter().zip(&sb) {
        assert_eq!(ka, kb);
        let same = a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same, "checkpointed {ka} differs");
    }
    let (log_a, log_b) = (read_log(&fa.log()).unwrap(), read_log(&fb.log()).unwrap());
    for (x, y) in log_a.iter().zip(&log_b) {
        assert_eq!((x.train_loss, x.val_loss), (y.train_loss, y.val_loss));
        assert_ne!(
            x.test_loss, y.test_loss,
            "the perturbation reached the test meshes"
        );
    }
    // The authors' protocol is still available, labelled, from its own weights file.
    assert!(fa.weights_selected_on_test().is_file());
    let on_test = TrainedModel::load_selected(&out_a, &Device::Cpu, true).unwrap();
    assert_eq!(on_test.selected_on, Selection::Test);
    let best_test = log_a
        .iter()
        .min_by(|x, y| x.test_loss.unwrap().total_cmp(&y.test_loss.unwrap()))
        .unwrap()
        .epoch;
    assert_eq!(on_test.epochs_trained().unwrap().1, best_test);
    // Weights of another epoch than run.json's choice (a resumed run that stopped keeping
    // them, say) are refused as stale.
    let status_path = fa.status();
    let mut status: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&status_path).unwrap()).unwrap();
    status["best_test_epoch"] = serde_json::json!(best_test + 100);
    std::fs::write(&status_path, status.to_string()).unwrap();
    let err = TrainedModel::load_selected(&out_a, &Device::Cpu, true)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("stale") && err.contains(&format!("epoch {best_test}")),
        "{err}"
    );
    // Without the option, run.json names the epoch and the error says how to keep them.
    assert!(!fb.weights_selected_on_test().is_file());
    let best_test_b = log_b
        .iter()
        .min_by(|x, y| x.test_loss.unwrap().total_cmp(&y.test_loss.unwrap()))
        .unwrap()
        .epoch;
    let status = meshvae::read_status(&fb).unwrap().unwrap();
    assert_eq!(status.best_test_epoch, Some(best_test_b));
    let err = TrainedModel::load_selected(&out_b, &Device::Cpu, true)
        .err()
        .unwrap()
        .to_string();
    let epoch = format!("epoch {best_test_b}");
    assert!(
        err.contains("--keep-selected-on-test") && err.contains(&epoch),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&out_a);
    let _ = std::fs::remove_dir_all(&out_b);
}

#[test]
fn copies_of_one_shape_stay_on_one_side_of_the_split() {
    // Every shape twice, as horse-gallop stores its gallop cycle.
    let once = small_set(5, 8);
    let n = once.len();
    let mut positions = Vec::new();
    let mut names = Vec::new();
    for copy in 0..2 {
        for (i, frame) in once.frames().enumerate() {
            positions.extend_from_slice(frame);
            names.push(format!("copy{copy}_{i:02}"));
        }
    }
    let twice =
        MeshSet::from_flat(once.faces().to_vec(), once.vertex_count(), positions, names).unwrap();
    let out = scratch("twins");
    let mut req = request(&twice, &out, 1);
    req.train.val_fraction = 0.25;
    train(&req, &options(false, false), |_| {}).unwrap();
    let folder = ModelFolder::new(&out);
    let file: SplitFile = folder.read_json(&folder.split()).unwrap();
    assert!(file.by_shape);
    let expected: Vec<Vec<usize>> = (0..n).map(|i| vec![i, i + n]).collect();
    assert_eq!(file.repeated_shapes, expected);
    let side = |i: usize| {
        (
            file.test.contains(&i),
            file.val.contains(&i),
            file.train.contains(&i),
        )
    };
    for i in 0..n {
        assert_eq!(side(i), side(i + n), "mesh {i} and its copy are split");
    }
    assert!(!file.test.is_empty() && !file.val.is_empty());
    assert_eq!(file.test.len(), n, "half of the shapes test");
    let trained = TrainedModel::load(&out, &Device::Cpu).unwrap();
    let report = trained.evaluate(&twice, &Device::Cpu).unwrap();
    assert_eq!(report.copies, None, "no test shape is trained on");

    // Opting out draws the test meshes one by one, exactly the plain random split...
    req.train.split_by_shape = false;
    train(&req, &options(false, true), |_| {}).unwrap();
    let file: SplitFile = folder.read_json(&folder.split()).unwrap();
    let plain = Split::random(2 * n, 0.5, req.train.seed).unwrap();
    assert!(!file.by_shape && file.repeated_shapes.is_empty());
    assert_eq!(file.test, plain.test);
    let mut trained_or_val = [file.train.clone(), file.val.clone()].concat();
    trained_or_val.sort_unstable();
    assert_eq!(trained_or_val, plain.train);
    // ...but validation shapes stay whole: no validation mesh has its copy among the training
    // meshes, so the validation loss measures unseen poses.
    let twin = |i: usize| (i + n) % (2 * n);
    assert!(!file.val.is_empty());
    for &i in &file.val {
        assert!(
            !file.train.contains(&twin(i)),
            "{i}'s copy trains: {file:?}"
        );
    }
    // Evaluation tells the test meshes whose copy trained from the others.
    let with_copy = file
        .test
        .iter()
        .filter(|&&i| file.train.contains(&twin(i)))
        .count();
    assert!(with_copy > 0 && with_copy < file.test.len(), "{file:?}");
    let trained = TrainedModel::load(&out, &Device::Cpu).unwrap();
    let report = trained.evaluate(&twice, &Device::Cpu).unwrap();
    let copies = report.copies.expect("some test shapes are trained on");
    let unseen = copies.unseen.expect("some are not");
    assert_eq!(copies.copy_in_training.meshes, with_copy);
    assert_eq!(unseen.meshes, file.test.len() - with_copy);
    // The two parts average to the whole (every mesh has as many vertices).
    let parts = copies.copy_in_training.mean_distance_rigid * with_copy as f64
        + unseen.mean_distance_rigid * unseen.meshes as f64;
    let whole = report.test.mean_distance_rigid * file.test.len() as f64;
    assert!(
        (parts - whole).abs() <= 1e-9 * whole.max(1e-12),
        "{parts} vs {whole}"
    );
    // A model trained by shape is not resumed as one drawn by mesh.
    let same = train(&req, &options(true, false), |_| {});
    assert!(same.is_ok(), "same settings resume: {same:?}");
    req.train.split_by_shape = true;
    let err = train(&req, &options(true, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("training settings"), "{err}");
    let _ = std::fs::remove_dir_all(&out);
}
