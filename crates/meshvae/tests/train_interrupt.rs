//! A run asked to stop (`TrainOptions::stop`, what Ctrl-C raises in the `meshvae` command)
//! writes its best state, says where it stopped, and resumes to the end of a run that was never
//! stopped, bit for bit.

mod common;

use common::{assert_same_run, looking_request, options, request, scratch, small_set};
use meshvae::{
    ModelFolder, StopFlag, StopReason, TrainOptions, VaeError, read_log, read_status, train,
};
use std::path::Path;

#[test]
fn a_stopped_run_writes_its_best_state_and_resumes_to_the_uninterrupted_end() {
    // Best state kept in memory until a write (small models), or written at once (large ones).
    for (in_memory, tag) in [(16usize << 20, "mem"), (0, "disk")] {
        let set = small_set(3, 8);
        let epochs = 14;
        let req = |out: &Path| looking_request(&set, out, epochs);
        // No timed write during the run: whatever the folder holds after the stop, the stop
        // wrote.
        let opts = |resume: bool, stop: Option<StopFlag>| TrainOptions {
            best_in_memory_params: in_memory,
            checkpoint_seconds: 1e9,
            test_every_steps: 1,
            stop,
            ..options(resume, false)
        };
        let whole = scratch(&format!("stop-whole-{tag}"));
        train(&req(&whole), &opts(false, None), |_| {}).unwrap();

        let parts = scratch(&format!("stop-parts-{tag}"));
        let stop = StopFlag::new();
        let stop_after = 9;
        let stopped = train(&req(&parts), &opts(false, Some(stop.clone())), |r| {
            if r.epoch == stop_after {
                stop.request();
            }
        });
        let folder = ModelFolder::new(&parts);
        let status = read_status(&folder).unwrap().unwrap();
        match stopped {
            Err(VaeError::Interrupted {
                dir,
                epoch,
                checkpoint,
            }) => {
                assert_eq!(dir, parts);
                // The next epoch's first step saw the flag; that epoch is dropped.
                assert_eq!(epoch, stop_after, "{tag}");
                assert_eq!(checkpoint, Some(status.best_epoch), "{tag}");
                assert!(status.best_epoch > 0 && status.best_epoch <= stop_after);
            }
            other => panic!("{tag}: expected an interruption, got {other:?}"),
        }
        assert_eq!(status.stop_reason, StopReason::Interrupted);
        assert_eq!(status.epochs, stop_after);
        let log = read_log(&folder.log()).unwrap();
        assert_eq!(log.len(), stop_after);
        // The step the stop cut short is not counted: run.json's steps are its epochs'.
        assert!(status.steps_per_epoch > 1);
        assert_eq!(status.steps, log[stop_after - 1].step, "{tag}");
        assert!(folder.checkpoint().is_file() && folder.weights().is_file());
        assert!(!parts.join("training.lock").exists(), "{tag}: lock kept");

        let resumed = train(&req(&parts), &opts(true, None), |_| {}).unwrap();
        assert_eq!(resumed.epochs_run, epochs - status.best_epoch, "{tag}");
        assert_same_run(&whole, &parts, tag);
        let _ = std::fs::remove_dir_all(&whole);
        let _ = std::fs::remove_dir_all(&parts);
    }
}

#[test]
fn a_run_stopped_in_its_first_epoch_leaves_no_checkpoint_and_restarts() {
    let set = small_set(3, 8);
    let dir = scratch("stop-first");
    let stop = StopFlag::new();
    stop.request();
    let opts = |resume: bool, stop: Option<StopFlag>| TrainOptions {
        stop,
        ..options(resume, false)
    };
    match train(&request(&set, &dir, 3), &opts(false, Some(stop)), |_| {}) {
        Err(VaeError::Interrupted {
            epoch: 0,
            checkpoint: None,
            ..
        }) => {}
        other => panic!("expected an interruption before any epoch, got {other:?}"),
    }
    let folder = ModelFolder::new(&dir);
    assert!(!folder.checkpoint().exists());
    let status = read_status(&folder).unwrap().unwrap();
    assert_eq!(
        (status.stop_reason, status.epochs),
        (StopReason::Interrupted, 0)
    );
    let resumed = train(&request(&set, &dir, 3), &opts(true, None), |_| {}).unwrap();
    assert_eq!(resumed.epochs_run, 3);
    let _ = std::fs::remove_dir_all(&dir);
}
