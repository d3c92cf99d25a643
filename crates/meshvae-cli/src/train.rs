//! `meshvae train`: the flags resolved over a resumed model's settings or the network's
//! defaults, the run, and a report of how it ended.

use crate::{CliError, print_warnings};
use deform_features::FeatureOptions;
use mesh_hierarchy::{DepoolMode, HierarchyConfig};
use mesh_io::MeshSet;
use meshvae::{
    ConvKind, ModelConfig, ModelFolder, ModelSpec, Network, Pooler, Schedule, Split, StopFlag,
    StopReason, Structure, TrainConfig, TrainOptions, TrainRequest, TrainSummary, VaeError,
};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct TrainArgs {
    /// The mesh set: a folder of meshes, a multi-frame .glb, or a .mvset cache.
    set: PathBuf,
    /// The model folder to write (refused if it holds another model, unless --force/--resume).
    #[arg(long)]
    out: PathBuf,
    /// Budget in epochs (instead of the default step budget). Training still stops earlier
    /// once the validation loss has converged, unless --patience 0. With --resume, may be
    /// raised to train further.
    #[arg(long, conflicts_with = "steps")]
    epochs: Option<usize>,
    /// Budget in optimizer steps (rounded up to whole epochs) [default: 20000, which the sets
    /// measured never reach: they converge first]. With --resume, may be raised.
    #[arg(long)]
    steps: Option<usize>,
    /// Stop (converged) after this many optimizer steps without a new best validation loss
    /// (after the decay, if any); 0 trains the whole budget [default: 200].
    #[arg(long)]
    patience: Option<usize>,
    /// A new best counts (for --patience) only when it lies this fraction below the best that
    /// last counted [default: 0.01].
    #[arg(long)]
    min_improvement: Option<f64>,
    /// Without a decay (--decay 0): halve the learning rate after this many steps without a
    /// new best (at most five times); 0 keeps it constant [default: 0; 400 was the default
    /// before the cosine decay].
    #[arg(long)]
    lr_patience: Option<usize>,
    /// Raise the learning rate linearly from a tenth over this many first steps [default: 300].
    #[arg(long)]
    warmup: Option<usize>,
    /// Cut the rate and stop on a moving average of the validation loss over about this many
    /// steps, not on the noisy loss itself; 0 = the loss itself [default: 0].
    #[arg(long)]
    smoothing: Option<usize>,
    /// Let the rate fall along a half cosine to 1/32 of --lr over this many steps after the
    /// warm-up (no plateau cuts; the run stops once the decay has ended and --patience steps
    /// pass without a new best); 0 cuts the rate on plateaus (see --lr-patience) [default:
    /// 1200].
    #[arg(long)]
    decay: Option<usize>,
    /// Scale a step's gradient down to K times the running mean of the recent gradient norms
    /// when it is larger (a blow-up's first step); 0 never clips [default: 3].
    #[arg(long, value_name = "K")]
    clip: Option<f64>,
    /// Measure the validation loss only once this many steps have passed since the last
    /// time (and at the end); 0 or 1 measures it after every epoch [default: 10].
    #[arg(long)]
    validate_every: Option<usize>,
    /// Adam's β₂ [default: 0.95; TF's and the authors' is 0.999].
    #[arg(long)]
    beta2: Option<f64>,
    /// The dense heads' weights (W_μ, W_σ, tens of thousands of inputs per latent unit) train
    /// at this fraction of the rate [default: 0.3; the authors train all at one rate].
    #[arg(long)]
    head_lr_scale: Option<f64>,
    /// Seeds the split, the initial weights, the shuffles and the sampling [default: 1].
    #[arg(long)]
    seed: Option<u64>,
    /// The auto-encoder: ours (the paper's), or one it is compared with, as its authors define
    /// it: tan2018 (Tan et al.'s fully connected mesh VAE, on the same features), coma (CoMA,
    /// on positions) or spiralnet (SpiralNet++, on positions). The others take their own
    /// layers, latent size, loss and rate (1e-3), and the same split, schedule and stopping
    /// rule as ours [default: ours].
    #[arg(long)]
    net: Option<Network>,
    /// Layers: C = convolution, P = pooling [default: CCPC].
    #[arg(long)]
    structure: Option<Structure>,
    /// Convolution: spectral (Chebyshev) or spatial [default: spectral].
    #[arg(long)]
    conv: Option<ConvKind>,
    /// Pooling: mean (ours: modified QEM), max, qem (classical QEM), sampling (CoMA), remesh
    /// (uniform remeshing, mean over nearest-vertex clusters), graph (graph max pooling, Shen
    /// et al. 2018), none [default: mean].
    #[arg(long)]
    pool: Option<Pooler>,
    /// Meshes per step [default: 50].
    #[arg(long)]
    batch: Option<usize>,
    /// Adam's initial learning rate (the peak after a warm-up; the schedule lowers it)
    /// [default: 0.01; the authors: 0.001, constant].
    #[arg(long)]
    lr: Option<f64>,
    /// Chebyshev order K [default: 3].
    #[arg(long)]
    k: Option<usize>,
    /// Latent size [default: 128].
    #[arg(long)]
    latent: Option<usize>,
    /// Channels of every hidden convolution [default: 9].
    #[arg(long)]
    channels: Option<usize>,
    /// Loss weights rec,kl,l2 [default: 40,3,1 as the authors' code].
    #[arg(long, value_parser = parse_weights)]
    loss_weights: Option<[f64; 3]>,
    /// A file of training mesh names (one per line); with --test-list instead of a random split.
    #[arg(long, requires = "test_list")]
    train_list: Option<PathBuf>,
    /// A file of test mesh names (one per line).
    #[arg(long, requires = "train_list")]
    test_list: Option<PathBuf>,
    /// A file of validation mesh names (one per line), with --train-list and --test-list;
    /// otherwise the validation meshes are drawn from the training ones (--val-fraction).
    #[arg(long, requires = "train_list")]
    val_list: Option<PathBuf>,
    /// Fraction of the training meshes moved to the validation set, whose loss alone chooses
    /// the best checkpoint (at least one mesh, two from ten training meshes on; 0 = choose on the training loss)
    /// [default: 0.1].
    #[arg(long)]
    val_fraction: Option<f64>,
    /// Draw the random test meshes one by one, even where the set holds the same shape more
    /// than once, as the paper's authors did (by default copies of a shape stay on one side,
    /// so no test shape is also a training mesh). Validation shapes are still drawn whole.
    #[arg(long)]
    split_by_mesh: bool,
    /// Train a conditional VAE on these labels: a CSV of `file,label` lines, one per mesh
    /// (generate with `meshvae generate --label L`).
    #[arg(long, conflicts_with = "conditional")]
    labels: Option<PathBuf>,
    /// Train a conditional VAE on the set's own labels (its folder's labels.csv, or a labelled
    /// .mvset such as `meshvae pack` of several sets writes).
    #[arg(long)]
    conditional: bool,
    /// De-pooling: copy (each fine vertex gets its coarse value) or transpose (the authors':
    /// divided by the cluster size) [default: copy].
    #[arg(long)]
    depool: Option<DepoolMode>,
    /// Features without the integrability correction (smoother, inexact round trip).
    #[arg(long)]
    plain_features: bool,
    /// No batch norm after the convolutions (the authors' code has it).
    #[arg(long)]
    no_batch_norm: bool,
    /// tanh on the last encoder convolution, as the authors' code (the paper's text: linear).
    #[arg(long)]
    last_encoder_tanh: bool,
    /// Fit the feature normalisation on every mesh, test meshes included, as the authors' code
    /// (for comparisons: the test meshes then shape the model's inputs).
    #[arg(long)]
    normalize_on_all: bool,
    /// Fit each feature group's range between the quantiles Q and 1 − Q and clamp the
    /// outliers; 0 fits it between min and max, as the authors' code [default: 0.001].
    #[arg(long)]
    normalize_quantile: Option<f64>,
    /// Continue the model in --out from its checkpoint (the best epoch's state: the epochs
    /// after it are trained again, to the same weights).
    #[arg(long, conflicts_with = "force")]
    resume: bool,
    /// Replace a model already in --out.
    #[arg(long)]
    force: bool,
    /// Write the best weights and their checkpoint at most this often (and after the last
    /// epoch); a kill loses the epochs since the best one written.
    #[arg(long, default_value_t = 60.0)]
    checkpoint_seconds: f64,
    /// Also keep the weights with the lowest TEST loss (weights-selected-on-test.safetensors,
    /// as large as the model) for `meshvae eval --select-on-test`, the authors' protocol;
    /// otherwise run.json records only their epoch and loss.
    #[arg(long)]
    keep_selected_on_test: bool,
    /// Measure the test loss (only watched: it chooses nothing, and measuring it changes no
    /// weight) once this many optimizer steps have passed since the last time, and after the
    /// last epoch; 0 or 1 measures it after every epoch [default: 50; 10 with
    /// --keep-selected-on-test, whose weights it chooses].
    #[arg(long, value_name = "N")]
    test_every: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Train through candle's autograd instead of the hand-written CPU step (slower; the two
    /// agree to rounding, see `meshvae::EngineExecutor`).
    #[arg(long)]
    no_engine: bool,
}

fn parse_weights(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|e| format!("`{p}`: {e}")))
        .collect::<Result<_, _>>()?;
    <[f64; 3]>::try_from(parts).map_err(|_| "expected three numbers rec,kl,l2".to_string())
}

fn load(path: &Path) -> Result<MeshSet, CliError> {
    let loaded = mesh_io::load_set(path)?;
    print_warnings(&loaded.warnings);
    Ok(loaded.value)
}

fn read_list(path: &Path) -> Result<Vec<String>, CliError> {
    let text = std::fs::read_to_string(path).map_err(|e| CliError::Output {
        path: path.into(),
        message: e.to_string(),
    })?;
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(String::from)
        .collect())
}

/// The flags that shape our network only, refused with another one (which is fixed as its
/// authors define it), rather than silently ignored.
fn refuse_ours_only_flags(args: &TrainArgs, net: Network) -> Result<(), CliError> {
    if net.is_ours() {
        return Ok(());
    }
    let given = [
        ("--structure", args.structure.is_some()),
        ("--conv", args.conv.is_some()),
        ("--pool", args.pool.is_some()),
        ("--k", args.k.is_some()),
        ("--channels", args.channels.is_some()),
        ("--no-batch-norm", args.no_batch_norm),
        ("--last-encoder-tanh", args.last_encoder_tanh),
        ("--depool", args.depool.is_some()),
        ("--labels", args.labels.is_some()),
        ("--conditional", args.conditional),
    ];
    match given.iter().find(|(_, on)| *on) {
        Some((flag, _)) => Err(CliError::argument(
            flag,
            format!(
                "shapes our network only; --net {net} is fixed as {}",
                net.defined_by()
            ),
        )),
        None => Ok(()),
    }
}

pub fn run_train(args: &TrainArgs) -> Result<(), CliError> {
    let set = load(&args.set)?;
    let folder = ModelFolder::new(&args.out);
    // Resuming: every setting not given again comes from the model's own config.
    let stored = args.resume.then(|| folder.read_spec()).transpose()?;
    let set = attach_labels(set, args, stored.as_ref())?;
    // --net, else the resumed model's network, else ours.
    let net = (args.net)
        .or(stored.as_ref().map(|s| s.model.net))
        .unwrap_or_default();
    refuse_ours_only_flags(args, net)?;
    let request = train_request(args, &set, net, stored.as_ref())?;
    let options = TrainOptions {
        stop: Some(StopFlag::on_interrupt()),
        ..train_options(args)
    };
    let summary = meshvae::train(&request, &options, |_| {}).map_err(|e| match e {
        VaeError::Interrupted { .. } => CliError::Interrupted {
            source: e,
            next: format!(
                "continue it with: meshvae train {} --out {} --resume",
                shell_word(&args.set),
                shell_word(&args.out)
            ),
        },
        e => e.into(),
    })?;
    report_run(&summary);
    report_stop(&summary, request.train.schedule.patience, args);
    report_outputs(&folder, &request.model.labels, &args.out);
    Ok(())
}

/// `path` as one word of a shell command: quoted when it holds anything but plain characters.
pub(crate) fn shell_word(path: &Path) -> String {
    let text = path.display().to_string();
    let plain = |c: char| c.is_ascii_alphanumeric() || "/._-+=:,@".contains(c);
    if !text.is_empty() && text.chars().all(plain) {
        text
    } else {
        format!("'{}'", text.replace('\'', r"'\''"))
    }
}

/// The set with the labels a conditional model trains on: a --labels file's, or those a
/// resumed model was trained with (they may have come from a --labels file rather than the
/// set).
fn attach_labels(
    set: MeshSet,
    args: &TrainArgs,
    stored: Option<&ModelSpec>,
) -> Result<MeshSet, CliError> {
    if let Some(path) = &args.labels {
        let labels = mesh_io::labels::read_labels(path, set.names())?;
        return Ok(set.with_labels(labels)?);
    }
    if let Some(spec) = stored
        && let Some(labels) = &spec.labels
        && set.labels().is_none()
        && set.names() == spec.names.as_slice()
    {
        return Ok(set.with_labels(labels.clone())?);
    }
    Ok(set)
}

/// What to train: the flags given, over the resumed model's settings or else `net`'s
/// defaults.
fn train_request<'a>(
    args: &TrainArgs,
    set: &'a MeshSet,
    net: Network,
    stored: Option<&ModelSpec>,
) -> Result<TrainRequest<'a>, CliError> {
    Ok(TrainRequest {
        set,
        model: model_config(args, set, net, stored)?,
        train: train_config(args, net, stored),
        features: feature_options(args, stored),
        hierarchy: hierarchy_config(args, stored),
        split: split_from_lists(args, set)?,
        source: std::fs::canonicalize(&args.set).ok(),
        out: args.out.clone(),
    })
}

/// The network's shape: our network's flags (refused for the others before this) over the
/// base configuration, made conditional on the set's labels if asked.
fn model_config(
    args: &TrainArgs,
    set: &MeshSet,
    net: Network,
    stored: Option<&ModelSpec>,
) -> Result<ModelConfig, CliError> {
    let base = stored
        .map(|s| s.model.clone())
        .unwrap_or_else(|| ModelConfig::for_network(net));
    let model = ModelConfig {
        net,
        structure: args.structure.clone().unwrap_or(base.structure.clone()),
        conv: args.conv.unwrap_or(base.conv),
        pool: args.pool.unwrap_or(base.pool),
        k: args.k.unwrap_or(base.k),
        latent: args.latent.unwrap_or(base.latent),
        channels: args.channels.unwrap_or(base.channels),
        batch_norm: base.batch_norm && !args.no_batch_norm,
        last_encoder_linear: base.last_encoder_linear && !args.last_encoder_tanh,
        ..base
    };
    if args.labels.is_none() && !args.conditional {
        return Ok(model);
    }
    let labels = set.labels().ok_or_else(|| {
        CliError::argument(
            "--conditional",
            format!(
                "{} has no labels (no labels.csv beside its meshes); pass --labels FILE",
                args.set.display()
            ),
        )
    })?;
    Ok(model.conditional_on(labels))
}

/// The training settings given, over the resumed model's, or else `net`'s defaults with the
/// command's own budget.
fn train_config(args: &TrainArgs, net: Network, stored: Option<&ModelSpec>) -> TrainConfig {
    let mut train = stored.map(|s| s.train.clone()).unwrap_or(TrainConfig {
        epochs: 300,
        steps: Some(meshvae::DEFAULT_MAX_STEPS),
        ..TrainConfig::for_network(net)
    });
    set_budget(&mut train, args);
    set_schedule(&mut train.schedule, args);
    set_step(&mut train, args);
    set_data(&mut train, args);
    train
}

/// --epochs replaces the step budget; --steps alone keeps the epochs as they were.
fn set_budget(train: &mut TrainConfig, args: &TrainArgs) {
    match (args.epochs, args.steps) {
        (Some(epochs), _) => {
            train.epochs = epochs;
            train.steps = None;
        }
        (None, Some(steps)) => train.steps = Some(steps),
        (None, None) => {}
    }
}

/// Warm-up, decay, plateau cuts, stopping and how often the validation loss is measured.
fn set_schedule(schedule: &mut Schedule, args: &TrainArgs) {
    if let Some(p) = args.patience {
        schedule.patience = p;
    }
    if let Some(x) = args.min_improvement {
        schedule.min_improvement = x;
    }
    if let Some(p) = args.lr_patience {
        schedule.lr_patience = p;
    }
    if let Some(n) = args.smoothing {
        schedule.smoothing_steps = n;
    }
    if let Some(w) = args.warmup {
        schedule.warmup_steps = w;
    }
    if let Some(d) = args.decay {
        schedule.decay_steps = d;
    }
    if let Some(n) = args.validate_every {
        schedule.validate_every_steps = n;
    }
}

/// What one step does: its batch, the loss weights and Adam's settings.
fn set_step(train: &mut TrainConfig, args: &TrainArgs) {
    train.lr = args.lr.unwrap_or(train.lr);
    train.batch = args.batch.unwrap_or(train.batch);
    if let Some(b) = args.beta2 {
        train.adam_beta2 = b;
    }
    if let Some(x) = args.head_lr_scale {
        train.head_lr_scale = x;
    }
    if let Some(k) = args.clip {
        train.grad_clip = k;
    }
    if let Some([rec, kl, l2]) = args.loss_weights {
        train.loss.rec = rec;
        train.loss.kl = kl;
        train.loss.l2 = l2;
    }
}

/// The seed, the split's rules and the feature normalisation.
fn set_data(train: &mut TrainConfig, args: &TrainArgs) {
    train.seed = args.seed.unwrap_or(train.seed);
    train.val_fraction = args.val_fraction.unwrap_or(train.val_fraction);
    train.split_by_shape = !args.split_by_mesh && train.split_by_shape;
    train.normalize_on_all = train.normalize_on_all || args.normalize_on_all;
    train.normalize_quantile = args.normalize_quantile.unwrap_or(train.normalize_quantile);
}

/// A resumed model keeps its features (--plain-features applies to new models only).
fn feature_options(args: &TrainArgs, stored: Option<&ModelSpec>) -> FeatureOptions {
    stored.map(|s| s.features).unwrap_or(FeatureOptions {
        integrable: !args.plain_features,
        ..FeatureOptions::default()
    })
}

fn hierarchy_config(args: &TrainArgs, stored: Option<&ModelSpec>) -> HierarchyConfig {
    let base = stored.map(|s| s.hierarchy).unwrap_or_default();
    HierarchyConfig {
        depool: args.depool.unwrap_or(base.depool),
        ..base
    }
}

/// The split the --train-list, --test-list (and --val-list) files give; `None` lets training
/// draw one from the seed.
fn split_from_lists(args: &TrainArgs, set: &MeshSet) -> Result<Option<Split>, CliError> {
    let (Some(train), Some(test)) = (&args.train_list, &args.test_list) else {
        return Ok(None);
    };
    let val = match &args.val_list {
        Some(v) => read_list(v)?,
        None => Vec::new(),
    };
    let split = Split::from_names(set.names(), &read_list(train)?, &val, &read_list(test)?)?;
    Ok(Some(split))
}

fn train_options(args: &TrainArgs) -> TrainOptions {
    TrainOptions {
        resume: args.resume,
        force: args.force,
        progress: !args.quiet,
        checkpoint_seconds: args.checkpoint_seconds,
        keep_selected_on_test: args.keep_selected_on_test,
        // A pass over the test half costs a whole step on horse-gallop and four on samba, and
        // the curve it draws needs no more than a point every 50 steps.
        test_every_steps: args.test_every.unwrap_or(if args.keep_selected_on_test {
            10
        } else {
            50
        }),
        device: meshvae::default_device(),
        engine: !args.no_engine,
        ..TrainOptions::default()
    }
}

/// How long the run trained, how far it got, its best epoch and what computed its steps.
fn report_run(summary: &TrainSummary) {
    let done = summary
        .last
        .as_ref()
        .map_or(0, |r| r.epoch)
        .max(summary.best_epoch);
    out!(
        "trained {} epoch(s) in {:.1} s ({} of at most {} epochs, {} steps, {:.0} s in all); best \
         epoch {} ({} loss {:.4})",
        summary.epochs_run,
        summary.seconds,
        done,
        summary.epochs_total,
        summary.steps,
        summary.seconds_total,
        summary.best_epoch,
        summary.selected_on,
        summary.best_loss
    );
    if let Some(executor) = &summary.executor {
        out!("steps computed by: {executor}");
    }
}

/// Why the run stopped. A budget that cut the loss while it still improved is a warning that
/// says how to continue.
fn report_stop(summary: &TrainSummary, patience: usize, args: &TrainArgs) {
    match summary.stop_reason {
        StopReason::Converged => out!(
            "stopped: converged (no new best {} loss for {} steps; learning rate now {:.2e})",
            summary.selected_on,
            patience,
            summary.lr
        ),
        _ if summary.still_improving => eprintln!(
            "warning: stopped by the budget ({} steps) while the {} loss was still improving: \
             the model has not finished learning. Continue it with `meshvae train {} --out {} \
             --resume --steps N` and a larger N.",
            summary.steps,
            summary.selected_on,
            args.set.display(),
            args.out.display()
        ),
        _ => out!("stopped: budget (the loss had stopped improving)"),
    }
}

/// The loss plot (a failure to draw it only warns: the model is written), a conditional
/// model's labels and where the model is.
fn report_outputs(folder: &ModelFolder, labels: &[String], model_dir: &Path) {
    match crate::loss_plot::write_loss_plot(folder) {
        Ok(path) => out!("loss curves: {}", path.display()),
        Err(e) => eprintln!("warning: no loss.png: {e}"),
    }
    if !labels.is_empty() {
        out!("conditional on the labels {}", labels.join(", "));
    }
    out!("model: {}", model_dir.display());
}
