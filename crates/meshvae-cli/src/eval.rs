//! `meshvae eval`: the errors of a trained model on its test meshes, how its training stopped,
//! and its loss curves.

use crate::CliError;
use crate::generate::model_and_set_selected;
use meshvae::ModelFolder;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct EvalArgs {
    /// A model folder written by `meshvae train`.
    model: PathBuf,
    /// The mesh set (default: the one the model was trained on, as recorded in its config).
    #[arg(long)]
    set: Option<PathBuf>,
    /// Print one JSON object (keys: net (ours, tan2018, coma or spiralnet), test_rms, test_rms_x1000, test_rms_rel, train_rms,
    /// train_rms_rel, mean_shape_rms, mean_shape_rms_rel, test_mean_distance,
    /// test_mean_distance_rigid, mean_shape_mean_distance_rigid, test_copy_in_training_meshes,
    /// test_copy_in_training_mean_distance_rigid, test_unseen_meshes,
    /// test_unseen_mean_distance_rigid (null unless the split put copies of test shapes among
    /// the training meshes), params,
    /// params_without_biases, epochs, best_epoch, selected_on, stop_reason, steps,
    /// still_improving, train_seconds, rollbacks, clipped_steps (null without --clip), phases (seconds by phase of training), loss_spike_epochs (epochs whose training
    /// loss exceeds 3× the median of the 50 before them), vertices, test_meshes, val_meshes, train_meshes,
    /// split_by_shape, loss_plot, warnings: [{kind, message}] when the test error is not clearly
    /// below the mean training shape's or training was cut while still improving).
    #[arg(long)]
    json: bool,
    /// Report the weights with the lowest TEST loss, as the authors' code chose its checkpoint
    /// (for comparison only: errors selected on the test meshes are not errors on unseen data).
    #[arg(long)]
    select_on_test: bool,
}

pub fn run_eval(args: &EvalArgs) -> Result<(), CliError> {
    let (trained, set) =
        model_and_set_selected(&args.model, args.set.as_ref(), args.select_on_test)?;
    let report = trained.evaluate(&set, &meshvae::default_device())?;
    let epochs = trained.epochs_trained()?;
    let folder = ModelFolder::new(&args.model);
    let status = meshvae::read_status(&folder)?;
    // No log and no run.json: weights written by another program (meshvae.torch's `save`),
    // whose training this folder does not record.
    let recorded = status.is_some() || folder.log().is_file();
    // Redrawn when missing or older than the log (a run killed before it drew one).
    let loss_plot = match recorded {
        true => crate::loss_plot::refresh_loss_plot(&folder)
            .map_err(|e| eprintln!("warning: no loss.png: {e}"))
            .ok(),
        false => None,
    };
    // Models trained before run.json existed: a full log ran its budget.
    let stop_reason = match &status {
        Some(s) => s.stop_reason.as_str(),
        None if !recorded => "unrecorded",
        None if epochs.0 >= trained.spec.train.epochs => "budget",
        None => "interrupted",
    };
    let warnings = meshvae::quality_warnings(&report, status.as_ref());
    let warnings_json = crate::generate::print_quality(&warnings);
    // Finite blow-ups, which the rollback does not see (it reacts to a non-finite loss).
    let log = match folder.log().is_file() {
        true => meshvae::read_log(&folder.log())?,
        false => Vec::new(),
    };
    let spikes = meshvae::loss_spikes(&log, meshvae::SPIKE_WINDOW, meshvae::SPIKE_FACTOR);
    let copy_in_training = report.copies.map(|c| c.copy_in_training);
    let unseen = report.copies.and_then(|c| c.unseen);
    let net = trained.spec.model.net;
    let value = serde_json::json!({
        "net": net.to_string(),
        "test_rms": report.test.rms,
        "test_rms_x1000": report.test.rms_x1000,
        "test_rms_rel": report.test.rms_rel,
        "test_mean_distance": report.test.mean_distance,
        "test_mean_distance_rigid": report.test.mean_distance_rigid,
        "mean_shape_mean_distance_rigid": report.mean_shape.mean_distance_rigid,
        "test_copy_in_training_meshes": copy_in_training.map(|r| r.meshes),
        "test_copy_in_training_mean_distance_rigid":
            copy_in_training.map(|r| r.mean_distance_rigid),
        "test_unseen_meshes": unseen.map(|r| r.meshes),
        "test_unseen_mean_distance_rigid": unseen.map(|r| r.mean_distance_rigid),
        "train_rms": report.train.rms,
        "train_rms_rel": report.train.rms_rel,
        "mean_shape_rms": report.mean_shape.rms,
        "mean_shape_rms_rel": report.mean_shape.rms_rel,
        "params": report.params.with_biases,
        "params_without_biases": report.params.without_biases,
        "epochs": recorded.then_some(epochs.0),
        "best_epoch": recorded.then_some(epochs.1),
        "selected_on": trained.selected_on.as_str(),
        "stop_reason": stop_reason,
        "steps": status.as_ref().map(|s| s.steps),
        "still_improving": status.as_ref().map(|s| s.still_improving),
        "train_seconds": status.as_ref().map(|s| s.seconds),
        "rollbacks": status.as_ref().map(|s| s.rollbacks),
        "clipped_steps": status.as_ref().and_then(|s| s.clipped_steps),
        "phases": status.as_ref().and_then(|s| s.phases),
        "loss_spike_epochs": spikes,
        "loss_plot": loss_plot.as_ref().map(|p| p.display().to_string()),
        "vertices": report.vertices,
        "test_meshes": report.test.meshes,
        "val_meshes": trained.split.val.len(),
        "train_meshes": report.train.meshes,
        "split_by_shape": trained.spec.train.split_by_shape,
        "warnings": warnings_json,
    });
    if args.json {
        let text = serde_json::to_string_pretty(&value)
            .map_err(|e| CliError::argument("--json", e.to_string()))?;
        out!("{text}");
        return Ok(());
    }
    out!("{}", args.model.display());
    if trained.selected_on == meshvae::Selection::Test {
        out!(
            "  SELECTED ON TEST: these weights had the lowest loss on the test meshes (the \
             authors' protocol); the test errors below are not errors on unseen data"
        );
    }
    out!(
        "  test RMS     {:.6} ({:.4} ×1000, {:.3e} of the bbox diagonal) over {} meshes",
        report.test.rms,
        report.test.rms_x1000,
        report.test.rms_rel,
        report.test.meshes
    );
    out!(
        "  train RMS    {:.6} ({:.3e} of the diagonal) over {} meshes",
        report.train.rms,
        report.train.rms_rel,
        report.train.meshes
    );
    out!(
        "  mean shape   {:.6} ({:.3e}): the trivial predictor, on the test meshes",
        report.mean_shape.rms,
        report.mean_shape.rms_rel
    );
    out!(
        "  mean dist.   {:.6} test, {:.6} mean shape (per-vertex, rigidly aligned as the authors' \
         script; {:.6} test with centroids aligned only)",
        report.test.mean_distance_rigid,
        report.mean_shape.mean_distance_rigid,
        report.test.mean_distance
    );
    if let Some(seen) = copy_in_training {
        out!(
            "  of which     {:.6} over the {} test meshes whose shape a training mesh repeats \
             (memory), {} over the {} others (generalisation)",
            seen.mean_distance_rigid,
            seen.meshes,
            unseen.map_or("–".into(), |r| format!("{:.6}", r.mean_distance_rigid)),
            unseen.map_or(0, |r| r.meshes),
        );
    }
    out!(
        "  parameters   {} ({} without biases)",
        report.params.with_biases,
        report.params.without_biases
    );
    if !net.is_ours() {
        out!("  network      {net}: {}", net.defined_by());
    }
    match recorded {
        true => out!(
            "  epochs       {} (weights of epoch {}, chosen on the {} loss; {} validation meshes)",
            epochs.0,
            epochs.1,
            trained.selected_on,
            trained.split.val.len()
        ),
        false => out!(
            "  epochs       unrecorded ({} validation meshes in the split)",
            trained.split.val.len()
        ),
    }
    match &status {
        Some(s) => out!(
            "  stopped      {}{} after {} steps, {:.0} s of training ({} path){}",
            s.stop_reason,
            if s.stop_reason == meshvae::StopReason::Budget && s.still_improving {
                " WHILE STILL IMPROVING (not finished learning; continue with --resume)"
            } else {
                ""
            },
            s.steps,
            s.seconds,
            s.path,
            if s.lr_cuts > 0 {
                format!("; learning rate cut {} times, to {:.2e}", s.lr_cuts, s.lr)
            } else {
                String::new()
            }
        ),
        None if !recorded => out!(
            "  stopped      unrecorded: the folder has no run.json or log.jsonl (weights written \
             by another program, such as meshvae.torch's save)"
        ),
        None => out!("  stopped      {stop_reason} (a model trained before run.json)"),
    }
    if let Some(p) = status.as_ref().and_then(|s| s.phases) {
        out!(
            "  time         {:.0} s: batches {:.0}, forward and backward {:.0}, Adam {:.0}, \
             validation {:.0}, test {:.0}, bookkeeping {:.0} (this process's part of the run)",
            p.total(),
            p.batches,
            p.forward_backward,
            p.adam,
            p.validation,
            p.test,
            p.bookkeeping
        );
    }
    if let Some(n) = status.as_ref().and_then(|s| s.clipped_steps) {
        out!("  clipped      {n} steps (gradient above --clip × its running mean)");
    }
    let rollbacks = status.as_ref().map_or(0, |s| s.rollbacks);
    if rollbacks > 0 || !spikes.is_empty() {
        let shown: Vec<String> = spikes.iter().take(8).map(usize::to_string).collect();
        out!(
            "  blow-ups     {rollbacks} rolled back (non-finite loss); {} epochs with a training \
             loss above {}× the median of the {} before{}",
            spikes.len(),
            meshvae::SPIKE_FACTOR,
            meshvae::SPIKE_WINDOW,
            if shown.is_empty() {
                String::new()
            } else {
                format!(
                    " (epochs {}{})",
                    shown.join(", "),
                    if spikes.len() > 8 { ", …" } else { "" }
                )
            }
        );
    }
    if let Some(path) = &loss_plot {
        out!("  loss curves  {}", path.display());
    }
    out!(
        "  split        {}",
        if trained.spec.train.split_by_shape {
            "random, by shape (copies of one shape on one side)"
        } else {
            "random, mesh by mesh"
        }
    );
    Ok(())
}
