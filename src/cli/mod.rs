//! The command-line interface: argument parsing (clap) and one module per subcommand.

mod animate;
mod bench;
mod chunks;
mod demo;
mod export;
mod fit;
mod inspect;
mod merge;
mod output;
mod report;
mod rig;
mod scene;
mod validate;
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
    /// Turn a blend-shape rig into wrinkled glTF frames (the main job).
    #[command(
        after_help = "Example:\n  furrow animate rigs/face.glb -o out/face_wrinkled.glb --report out/report.json --preview out/preview"
    )]
    Animate(animate::AnimateArgs),
    /// Animate many rigs; failures are reported and the rest go on; finished ones are skipped.
    #[command(
        after_help = "Example:\n  furrow batch clips/*.glb -o out/batch --scene examples/face.toml"
    )]
    Batch(animate::BatchArgs),
    /// Join chunk runs (`animate --frames A:B`) into one glTF identical to an unsplit run.
    #[command(
        after_help = "Example:\n  furrow merge out/part0.glb out/part1.glb --rig rigs/face.glb -o out/face_wrinkled.glb"
    )]
    Merge(merge::MergeArgs),
    /// Print a clip's frame ranges for a farm (one `A:B` per line), balanced by expected
    /// cost with a pre-roll per chunk; run each with `animate --frames A:B --preroll P`.
    #[command(
        after_help = "Example:\n  furrow chunks rigs/face.glb --count 4 --preroll 9\n  furrow animate rigs/face.glb --frames 0:104 --preroll 9 -o out/part_0.glb"
    )]
    Chunks(chunks::ChunksArgs),
    /// Run a synthetic scene (slab, cushions, cubes) and write its frames and wavelengths.
    #[command(after_help = "Example:\n  furrow scene examples/cushions.toml --out out/scenes")]
    Scene(scene::SceneArgs),
    /// Muscle activations per frame fitted to the blend-shape animation (CSV).
    #[command(
        after_help = "Example:\n  furrow fit rigs/face.glb -o activations.csv\n  furrow fit rigs/face.glb --frames 0:60 --gauss-newton 2 --json"
    )]
    Fit(fit::FitArgs),
    /// Validations of the physics: wrinkle wavelength against the formula and a dense simulation.
    #[command(
        subcommand,
        after_help = "Example:\n  furrow validate wavelength --out out/validate\n  furrow validate dense --quick"
    )]
    Validate(validate::ValidateCommand),
    /// Benchmarks that print or write their measurements.
    #[command(
        subcommand,
        after_help = "Example:\n  furrow bench shell --faces 20000\n  furrow bench lattice --elements 1000 --json"
    )]
    Bench(bench::BenchCommand),
    /// Measured reports: error against run time, stability on stiff and extreme cases.
    #[command(
        subcommand,
        after_help = "Example:\n  furrow report tradeoff --quick --out out/report\n  furrow report stability --out out/report"
    )]
    Report(report::ReportCommand),
}

/// The flag of every subcommand that loads a rig: whether its buffer and image files may lie
/// outside its folder.
#[derive(Debug, Clone, Copy, Default, clap::Args)]
pub struct RigPathsArgs {
    /// Read buffer and image files outside the rig's folder (absolute paths, `..`, symlinks
    /// out); refused by default.
    #[arg(long)]
    pub allow_outside_paths: bool,
}

impl RigPathsArgs {
    /// How the rig file is read.
    pub fn read(&self) -> crate::io::container::ReadOptions {
        crate::io::container::ReadOptions {
            allow_outside_paths: self.allow_outside_paths,
        }
    }
}

/// A failure whose details were already printed (in JSON mode, as the command's own result
/// document); `main` prints only the one-line message to stderr.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct AlreadyReported(pub String);

/// Parse the command line, run it, print errors; returns the process exit code
/// (0 success, 2 failure with a message naming the file and the problem).
pub fn main() -> i32 {
    let cli = Cli::parse();
    // faer splits large factorisations by this task count (not the pool size), so outputs
    // are byte-identical whatever RAYON_NUM_THREADS is.
    faer::set_global_parallelism(faer::Par::rayon(2));
    let out = Output::new(cli.quiet, cli.json);
    let result = match cli.command {
        Command::Inspect(a) => inspect::run(a, &out),
        Command::Rig(c) => rig::run(c, &out),
        Command::Demo(a) => demo::run(a, &out),
        Command::Wavelength(a) => wavelength::run(a, &out),
        Command::Fit(a) => fit::run(a, &out),
        Command::Bench(c) => bench::run(c, &out),
        Command::Animate(a) => animate::run(a, &out),
        Command::Batch(a) => animate::batch(a, &out),
        Command::Merge(a) => merge::merge(a, &out),
        Command::Chunks(a) => chunks::run(a, &out),
        Command::Scene(a) => scene::run(a, &out),
        Command::Validate(c) => validate::run(c, &out),
        Command::Report(c) => report::run(c, &out),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            if cli.json && e.downcast_ref::<AlreadyReported>().is_none() {
                let msg = format!("{e:#}");
                println!("{}", serde_json::json!({ "ok": false, "error": msg }));
            }
            eprintln!("furrow: error: {e:#}");
            2
        }
    }
}
