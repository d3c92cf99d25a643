//! `cargo xtask <task>`: project chores that are not part of the `meshvae` command.
//!
//! - `cargo xtask datasets [--pack DIR]`: checks that every standard data set is unpacked and
//!   has the expected counts; with `--pack`, writes each as a `.mvset` cache into DIR.
//! - `cargo xtask reproduce [--dataset …] [--epochs N] [--split-by-mesh] [--seeds N] [--quick]`:
//!   trains the paper's ablations on our data sets, each run until converged (or for N epochs),
//!   and writes `docs/results.md` or the page of its plan (see `xtask::reproduce`), a picture per
//!   data set beside it, and the page's summary into README.md between its markers.
//! - `cargo xtask reproduce --check RECORD`: trains one recorded run again and sets its numbers
//!   beside the stored ones.

use clap::{Parser, Subcommand};
use mesh_io::{QualityReport, datasets};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use xtask::reproduce::{self, Options, plan, plan::Budget};

// The `meshvae` command's allocator and settings, from its own file, so that timings of both
// agree.
#[path = "../../crates/meshvae-cli/src/alloc.rs"]
mod alloc;

#[derive(Parser)]
#[command(name = "cargo xtask")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Check the standard data sets (../shared/datasets or $MESHVAE_DATASETS) and optionally
    /// cache them.
    Datasets {
        /// Write `<name>.mvset` caches into this folder.
        #[arg(long)]
        pack: Option<PathBuf>,
    },
    /// Train the paper's ablations and structures on our data sets, several seeds each, and
    /// write the results beside the paper's numbers. Resumes an interrupted invocation.
    Reproduce(ReproduceArgs),
}

#[derive(clap::Args)]
struct ReproduceArgs {
    /// Data sets, comma-separated: horse-gallop, samba, elephant-gallop, synthetic, or all
    /// [default: horse-gallop,samba; with --quick: synthetic and horse-gallop when present].
    #[arg(long, value_delimiter = ',')]
    dataset: Vec<String>,
    /// Columns (network variants) to train, comma-separated, e.g. `ours,no-pool`; the results
    /// page still shows every finished run [default: all].
    #[arg(long, value_delimiter = ',')]
    columns: Vec<String>,
    /// Train every run for N epochs at the authors' constant learning rate of 1e-3 (runs and
    /// records under `e<N>/`, page `docs/results-<N>-epochs.md`) instead of until converged.
    #[arg(long)]
    epochs: Option<usize>,
    /// Train every run as `meshvae train` does by default, until the validation loss converges
    /// (learning rate 1e-2 after a warm-up, a cosine decay, stop 200 steps after the last new
    /// best once it has ended), at most 20,000 steps [with --quick: 4 steps]; runs and records live under `converged/`.
    /// This is the default; the flag only says so.
    #[arg(long, conflicts_with = "epochs")]
    converged: bool,
    /// Seeds 1..=N, one split each [default: 3; with --quick: 1].
    #[arg(long)]
    seeds: Option<u64>,
    /// Check the pipeline: a few epochs, one seed, a small synthetic set and horse-gallop.
    #[arg(long)]
    quick: bool,
    /// Folder of the runs' model folders and results [default: target/reproduce, with --quick
    /// target/reproduce/quick, in the workspace].
    #[arg(long)]
    work: Option<PathBuf>,
    /// The markdown to write [default, in the workspace: docs/results.md for converged runs
    /// split by shape, docs/results-split-by-mesh.md split mesh by mesh,
    /// docs/results-<N>-epochs.md for `--epochs N` (a `-split-by-mesh` or `-select-on-test`
    /// suffix for those plans); with --quick, results.md in the work folder].
    #[arg(long)]
    results: Option<PathBuf>,
    /// Folder of the finished runs' small result JSONs, in the work folder's layout [default:
    /// the work folder]. Point it at a folder under version control to resume a reproduction
    /// on another machine, or to regenerate the tables without the model folders.
    #[arg(long)]
    records: Option<PathBuf>,
    /// Runs trained at once, the cores shared evenly between them [default: 1, one run on all
    /// cores]. Two single-threaded runs finish sooner than two runs one after the other on two
    /// threads; the numbers are the same.
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// How the reported checkpoint is chosen: `validation` (10 % of the training half chooses
    /// it; no test mesh influences the model) or `select-on-test` (the authors' protocol: the
    /// test loss chooses it, so its errors are not on unseen data).
    #[arg(long, default_value = "validation")]
    protocol: String,
    /// Draw each seed's test half mesh by mesh, as the paper does, even where a set holds the
    /// same shape twice (horse-gallop's 48 meshes are one 24-frame cycle stored twice, so such
    /// halves test on shapes whose copies were trained on); by default copies stay on one side.
    #[arg(long)]
    split_by_mesh: bool,
    /// No progress bars.
    #[arg(long)]
    quiet: bool,
    /// Train nothing: write the results page from the runs already finished (a full
    /// reproduction spans several sessions).
    #[arg(long)]
    report_only: bool,
    /// Train the run of one result record (`…/seed<N>/<column>.result.json`) again, from
    /// scratch, with the settings it names, and print its numbers beside the stored ones; exits
    /// non-zero, saying why, unless every number agrees to the digit. Trains under
    /// `<work>/check`.
    #[arg(long, value_name = "RECORD", conflicts_with = "report_only")]
    check: Option<PathBuf>,
}

fn main() -> ExitCode {
    alloc::keep_freed_memory();
    match Cli::parse().task {
        Task::Datasets { pack } => check_datasets(pack),
        Task::Reproduce(args) => match run_reproduce(args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) if e.is_interrupted() => {
                eprintln!("error: {e}\nthe same command continues every run from its checkpoint");
                ExitCode::from(130)
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::FAILURE
            }
        },
    }
}

/// The workspace root (the parent of this package), for default paths that do not depend on
/// where `cargo xtask` is called from.
fn workspace() -> &'static Path {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest.parent().unwrap_or(manifest)
}

/// The error for a value of `arg` that names none of `names`.
fn not_one_of<'a>(
    arg: &'static str,
    value: &str,
    names: impl Iterator<Item = &'a str>,
) -> reproduce::ReproError {
    reproduce::ReproError::Argument {
        arg,
        message: format!(
            "{value:?} is not one of {}",
            names.collect::<Vec<_>>().join(", ")
        ),
    }
}

/// The step budget of `--quick`: enough to check the pipeline, far from converged.
const QUICK_MAX_STEPS: usize = 4;

/// The page of a plan, relative to the workspace: one page per plan, so that regenerating one
/// never overwrites another's hand-written notes. `docs/results.md` is the main plan's:
/// converged runs, split by shape, checkpoints chosen on validation meshes.
fn default_results(budget: Budget, by_shape: bool, protocol: &plan::Protocol) -> String {
    let mut name = match budget {
        Budget::Converged { .. } => "docs/results".to_string(),
        Budget::Epochs(epochs) => format!("docs/results-{epochs}-epochs"),
    };
    if !by_shape {
        name.push_str("-split-by-mesh");
    }
    if protocol.select_on_test {
        name.push_str("-select-on-test");
    }
    name + ".md"
}

fn run_reproduce(args: ReproduceArgs) -> Result<(), reproduce::ReproError> {
    let commit = reproduce::commit::Commit::compiled();
    if let Some(record) = &args.check {
        return run_check(record, &args, commit.as_ref());
    }
    let mut notes = Vec::new();
    let names: Vec<String> = if !args.dataset.is_empty() {
        args.dataset.clone()
    } else if args.quick {
        let mut names = vec!["synthetic".to_string()];
        if datasets::find("horse-gallop").is_some() {
            names.push("horse-gallop".into());
        } else {
            notes.push("horse-gallop was not found and was left out of the quick run.".into());
        }
        names
    } else {
        vec!["horse-gallop".into(), "samba".into()]
    };
    let mut chosen: Vec<&'static plan::Dataset> = Vec::new();
    for name in &names {
        if name == "all" {
            chosen.extend(plan::DATASETS.iter());
            continue;
        }
        let dataset = plan::dataset(name).ok_or_else(|| {
            let names = plan::DATASETS.iter().map(|d| d.name);
            not_one_of("--dataset", name, names.chain(["all"]))
        })?;
        chosen.push(dataset);
    }
    chosen.dedup_by_key(|d| d.name);
    let protocol = plan::protocol(&args.protocol).ok_or_else(|| {
        not_one_of(
            "--protocol",
            &args.protocol,
            plan::PROTOCOLS.iter().map(|p| p.id),
        )
    })?;
    let columns = if args.columns.is_empty() {
        plan::COLUMNS.iter().collect()
    } else {
        args.columns
            .iter()
            .map(|id| {
                plan::column(id)
                    .ok_or_else(|| not_one_of("--columns", id, plan::COLUMNS.iter().map(|c| c.id)))
            })
            .collect::<Result<Vec<_>, _>>()?
    };
    let default_work = if args.quick {
        workspace().join("target/reproduce/quick")
    } else {
        workspace().join("target/reproduce")
    };
    let budget = match args.epochs {
        Some(epochs) => Budget::Epochs(epochs),
        None => Budget::Converged {
            max_steps: if args.quick {
                QUICK_MAX_STEPS
            } else {
                meshvae::DEFAULT_MAX_STEPS
            },
        },
    };
    let by_shape = !args.split_by_mesh;
    let results = match args.results {
        Some(path) => path,
        None if args.quick => default_work.join("results.md"),
        None => workspace().join(default_results(budget, by_shape, protocol)),
    };
    let options = Options {
        datasets: chosen,
        columns,
        budget,
        seeds: args.seeds.unwrap_or(if args.quick { 1 } else { 3 }),
        quick: args.quick,
        protocol,
        by_shape,
        work: args.work.unwrap_or(default_work),
        records: args.records,
        jobs: args.jobs,
        results,
        command: std::iter::once("cargo xtask".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" "),
        progress: !args.quiet,
        report_only: args.report_only,
        commit,
    };
    let outcome = reproduce::reproduce(options, notes)?;
    println!(
        "{} runs ({} reused) in {:.1} min; wrote {}",
        outcome.results.len(),
        outcome.reused,
        outcome.wall_seconds / 60.0,
        outcome.options.results.display()
    );
    Ok(())
}

/// `--check RECORD`: the comparison on stdout; an error when a number differs.
fn run_check(
    record: &Path,
    args: &ReproduceArgs,
    commit: Option<&reproduce::commit::Commit>,
) -> Result<(), reproduce::ReproError> {
    let work = args
        .work
        .clone()
        .unwrap_or_else(|| workspace().join("target/reproduce"))
        .join("check");
    let checked = reproduce::check::check(record, &work, commit)?;
    print!("{}", checked.report());
    if checked.agrees() {
        Ok(())
    } else {
        Err(reproduce::ReproError::Results {
            path: record.to_path_buf(),
            message: "its numbers were not reproduced (see above)".into(),
        })
    }
}

fn check_datasets(pack: Option<PathBuf>) -> ExitCode {
    let Some(root) = datasets::root() else {
        eprintln!("no data sets found: run ../shared/datasets/unpack or set MESHVAE_DATASETS");
        return ExitCode::FAILURE;
    };
    println!("data sets in {}", root.display());
    let mut failures = 0;
    for &(name, meshes, vertices, faces, boundary) in datasets::KNOWN {
        let Some(dir) = datasets::find(name) else {
            println!("  {name:16} missing (run ../shared/datasets/unpack {name})");
            failures += 1;
            continue;
        };
        let set = match mesh_io::load_set(&dir) {
            Ok(loaded) => loaded.value,
            Err(e) => {
                println!("  {name:16} error: {e}");
                failures += 1;
                continue;
            }
        };
        let r = QualityReport::of(&set);
        let expected = (meshes, vertices, faces, boundary);
        let ok = (r.meshes, r.vertices, r.faces, r.boundary_edges) == expected;
        println!(
            "  {name:16} {} meshes, {} vertices, {} faces, {} boundary edges: {}",
            r.meshes,
            r.vertices,
            r.faces,
            r.boundary_edges,
            if ok { "ok" } else { "UNEXPECTED" }
        );
        failures += usize::from(!ok);
        if let Some(out) = &pack {
            let path = out.join(format!("{name}.mvset"));
            let written = std::fs::create_dir_all(out)
                .map_err(|e| e.to_string())
                .and_then(|()| mesh_io::cache::write_cache(&path, &set).map_err(|e| e.to_string()));
            match written {
                Ok(()) => println!("  {:16} wrote {}", "", path.display()),
                Err(e) => {
                    println!("  {name:16} cache error: {e}");
                    failures += 1;
                }
            }
        }
    }
    if failures == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_plan_has_its_own_page() {
        let [validation, on_test] = [&plan::PROTOCOLS[0], &plan::PROTOCOLS[1]];
        assert!(on_test.select_on_test && !validation.select_on_test);
        let page = |budget, by_shape, protocol| default_results(budget, by_shape, protocol);
        assert_eq!(page(Budget::CONVERGED, true, validation), "docs/results.md");
        assert_eq!(
            page(Budget::CONVERGED, false, validation),
            "docs/results-split-by-mesh.md"
        );
        assert_eq!(
            page(Budget::Epochs(600), true, validation),
            "docs/results-600-epochs.md"
        );
        assert_eq!(
            page(Budget::Epochs(600), false, on_test),
            "docs/results-600-epochs-split-by-mesh-select-on-test.md"
        );
    }
}
