//! `furrow bench …`: benchmarks printing their measurements (text or JSON).

use super::Output;

/// `furrow bench …` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// Skin solve: a square sheet of about N triangles under in-plane compression, centre
    /// clamped by constraints, solved to equilibrium from a warm start.
    #[command(
        after_help = "Example:\n  furrow bench shell --faces 20000\n  furrow bench shell --faces 2000 --json"
    )]
    Shell {
        /// Approximate triangle count.
        #[arg(long, default_value_t = 20_000)]
        faces: usize,
    },
    /// Interior step: one backward Euler step of a lattice of about N quadratic elements.
    #[command(after_help = "Example:\n  furrow bench lattice --elements 1000")]
    Lattice {
        /// Approximate element count.
        #[arg(long, default_value_t = 1000)]
        elements: usize,
    },
    /// Activation fit: 52 muscles on a face lattice of about N cells, a 335-frame clip.
    #[command(after_help = "Example:\n  furrow bench fit\n  furrow bench fit --cells 2000 --json")]
    Fit {
        /// Approximate lattice cell count over the face's bounding box.
        #[arg(long, default_value_t = 2000)]
        cells: usize,
        /// Frames timed with one Gauss–Newton re-linearisation.
        #[arg(long, default_value_t = 3)]
        gn_frames: usize,
    },
}

fn print(out: &Output, title: &str, v: &serde_json::Value) {
    out.json_result(v);
    out.say(title);
    if let Some(o) = v.as_object() {
        for (k, x) in o {
            out.say(format!("  {k:<22} {x}"));
        }
    }
}

/// Run a benchmark.
pub fn run(c: BenchCommand, out: &Output) -> anyhow::Result<()> {
    match c {
        BenchCommand::Shell { faces } => {
            anyhow::ensure!(
                (2..=5_000_000).contains(&faces),
                "--faces must be between 2 and 5,000,000, got {faces}"
            );
            print(
                out,
                "bench shell",
                &crate::shell::bench::bench_shell(faces)?,
            );
        }
        BenchCommand::Lattice { elements } => {
            anyhow::ensure!(
                (1..=1_000_000).contains(&elements),
                "--elements must be between 1 and 1,000,000, got {elements}"
            );
            print(
                out,
                "bench lattice",
                &crate::fem::bench::bench_lattice(elements)?,
            );
        }
        BenchCommand::Fit { cells, gn_frames } => {
            anyhow::ensure!(
                (1..=1_000_000).contains(&cells),
                "--cells must be between 1 and 1,000,000, got {cells}"
            );
            anyhow::ensure!(
                gn_frames <= 335,
                "--gn-frames must be at most 335, got {gn_frames}"
            );
            print(
                out,
                "bench fit",
                &crate::muscle::bench::bench_fit(cells, gn_frames)?,
            );
        }
    }
    Ok(())
}
