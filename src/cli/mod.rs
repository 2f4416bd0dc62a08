//! The command-line interface: argument parsing (clap) and one module per subcommand.

mod bench;
mod demo;
mod fit;
mod inspect;
mod output;
mod rig;
mod wavelength;

use clap::{Parser, Subcommand};
pub use output::Output;

/// furrow: physically wrinkled skin for blend-shape face animation (embedded thin shells).
#[derive(Debug, Parser)]
#[command(
    name = "furrow",
    version,
    about,
    long_about = None,
    propagate_version = true,
    after_help = "Example:\n  furrow demo --out out/demo\n  furrow inspect rigs/face.glb"
)]
pub struct Cli {
    /// Print nothing but errors (for pipelines).
    #[arg(long, global = true)]
    pub quiet: bool,
    /// Print results as one JSON document on stdout (for pipelines); implies no progress bars.
    #[arg(long, global = true)]
    pub json: bool,
    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// furrow's subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Show what a glTF file holds: meshes, counts, morph targets, animations, extensions.
    #[command(
        after_help = "Example:\n  furrow inspect rigs/face.glb\n  furrow inspect ../shared/data/RobotExpressive.glb --json"
    )]
    Inspect(inspect::InspectArgs),
    /// Make furrow's own rigs.
    #[command(
        subcommand,
        after_help = "Example:\n  furrow rig generate -o rigs/face.glb --force"
    )]
    Rig(rig::RigCommand),
    /// Run the main job on rigs/face.glb and print where the files went.
    #[command(after_help = "Example:\n  furrow demo --out out/demo")]
    Demo(demo::DemoArgs),
    /// The critical wrinkle wavelength λ of a skin on a soft interior (SI units).
    #[command(
        allow_negative_numbers = true,
        after_help = "Example:\n  furrow wavelength --thickness 0.0002 --skin-modulus 1e6 --interior-modulus 1e4"
    )]
    Wavelength(wavelength::WavelengthArgs),
    /// Muscle activations per frame fitted to the blend-shape animation (CSV).
    #[command(
        after_help = "Example:\n  furrow fit rigs/face.glb -o activations.csv\n  furrow fit rigs/face.glb --frames 0:60 --gauss-newton 2 --json"
    )]
    Fit(fit::FitArgs),
    /// Benchmarks that print or write their measurements.
    #[command(
        subcommand,
        after_help = "Example:\n  furrow bench shell --faces 20000\n  furrow bench lattice --elements 1000 --json"
    )]
    Bench(bench::BenchCommand),
}

/// Parse the command line, run it, print errors; returns the process exit code
/// (0 success, 2 failure with a message naming the file and the problem).
pub fn main() -> i32 {
    let cli = Cli::parse();
    let out = Output::new(cli.quiet, cli.json);
    let result = match cli.command {
        Command::Inspect(a) => inspect::run(a, &out),
        Command::Rig(c) => rig::run(c, &out),
        Command::Demo(a) => demo::run(a, &out),
        Command::Wavelength(a) => wavelength::run(a, &out),
        Command::Fit(a) => fit::run(a, &out),
        Command::Bench(c) => bench::run(c, &out),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            if cli.json {
                let msg = format!("{e:#}");
                println!("{}", serde_json::json!({ "ok": false, "error": msg }));
            }
            eprintln!("furrow: error: {e:#}");
            2
        }
    }
}
