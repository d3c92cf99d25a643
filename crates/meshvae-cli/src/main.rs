//! `meshvae`: a thin command over the pipeline's libraries. Each subcommand lives in a module
//! named for it; errors from every library become one message on stderr and exit code 1
//! (2 for usage errors, from clap).

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// `println!` for the commands' results: where standard output cannot be written (a full
/// disk, `> /dev/full`) the command ends with an error message and exit code 1 instead of a
/// panic.
macro_rules! out {
    () => {
        $crate::write_stdout(format_args!(""))
    };
    ($($arg:tt)*) => {
        $crate::write_stdout(format_args!($($arg)*))
    };
}

mod alloc;
mod demo;
mod embed;
mod error;
mod eval;
mod features;
mod generate;
mod info;
mod interpolate;
mod loss_plot;
mod pack;
mod reconstruct;
mod render;
mod roundtrip;
mod simplify;
mod synth;
mod train;

pub use error::CliError;

/// Train and use mesh variational autoencoders on sets of meshes that share one connectivity.
#[derive(Parser)]
#[command(name = "meshvae", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The whole pipeline on a built-in synthetic set in a few minutes: training, evaluation,
    /// generations, an interpolation, an embedding and pictures of each.
    Demo(demo::DemoArgs),
    /// Check a mesh set and print its counts and quality report.
    Info(info::InfoArgs),
    /// Write the synthetic bend/twist capsule set as OBJ files plus labels.csv.
    Synth(synth::SynthArgs),
    /// Pack a mesh set into one binary cache file (.mvset) that loads fast; several sets of one
    /// connectivity into one set labelled by set.
    Pack(pack::PackArgs),
    /// Compute the ACAP deformation features of a set (safetensors, normalisation as metadata).
    Features(features::FeaturesArgs),
    /// Features -> meshes for every frame; prints the reconstruction errors.
    Roundtrip(roundtrip::RoundtripArgs),
    /// Simplify a mesh (or a set's template) by quadric edge collapse with the edge-length
    /// term, or remesh it isotropically (`--method remesh`).
    Simplify(simplify::SimplifyArgs),
    /// Train a mesh VAE on a set; writes a model folder (resumable with --resume).
    Train(Box<train::TrainArgs>),
    /// Reconstruction errors of a trained model on its test and training meshes.
    Eval(eval::EvalArgs),
    /// Write a trained model's reconstructions of the test meshes (or all) as OBJ files.
    Reconstruct(reconstruct::ReconstructArgs),
    /// Render a mesh, or a grid of a set's meshes, to PNG (optionally coloured by the error
    /// against a ground truth).
    Render(render::RenderArgs),
    /// Random meshes from a trained model (z ~ N(0, I)), each with its nearest training mesh.
    Generate(generate::GenerateArgs),
    /// Decode the latent path between two meshes of the set: OBJ files, a GLB, a PNG strip.
    Interpolate(interpolate::InterpolateArgs),
    /// 2-D embeddings of the set (latent, PCA, t-SNE) as a CSV and scatter plots.
    Embed(embed::EmbedArgs),
}

fn main() -> ExitCode {
    alloc::keep_freed_memory();
    restore_default_sigpipe();
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Info(args) => info::run(args),
        Command::Synth(args) => synth::run(args),
        Command::Pack(args) => pack::run(args),
        Command::Features(args) => features::run_features(args),
        Command::Roundtrip(args) => roundtrip::run(args),
        Command::Simplify(args) => simplify::run(args),
        Command::Train(args) => train::run_train(args),
        Command::Eval(args) => eval::run_eval(args),
        Command::Reconstruct(args) => reconstruct::run(args),
        Command::Render(args) => render::run(args),
        Command::Generate(args) => generate::run(args),
        Command::Interpolate(args) => interpolate::run(args),
        Command::Embed(args) => embed::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code())
        }
    }
}

/// Rust ignores SIGPIPE, so `println!` into a closed pipe (`meshvae info … | head -1`) panics.
/// A command-line tool should end quietly instead, as `cat` does.
fn restore_default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called first thing in `main`, before any thread exists; SIG_DFL is a valid action.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// One line of [`out!`].
fn write_stdout(line: std::fmt::Arguments) {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    let written = stdout
        .write_fmt(line)
        .and_then(|()| stdout.write_all(b"\n"))
        .and_then(|()| stdout.flush());
    if let Err(e) = written {
        eprintln!("error: cannot write to standard output: {e}");
        std::process::exit(1);
    }
}

/// Prints the warnings met while reading, one per line on stderr.
pub fn print_warnings(warnings: &[mesh_io::Warning]) {
    for w in warnings {
        eprintln!("warning: {w}");
    }
}
