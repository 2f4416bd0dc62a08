//! `furrow bench …`: benchmarks printing their measurements (text or JSON).

use super::Output;

/// `furrow bench …` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// Skin solve: a square sheet of about N triangles under in-plane compression, centre
    /// clamped by constraints, solved to equilibrium from a warm start.
    #[command(after_help = "Example:\n  furrow bench shell --faces 20000\n  furrow bench shell --faces 2000 --json")]
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
            anyhow::ensure!((2..=5_000_000).contains(&faces), "--faces must be between 2 and 5,000,000, got {faces}");
            print(out, "bench shell", &crate::shell::bench::bench_shell(faces)?);
        }
        BenchCommand::Lattice { elements } => {
            anyhow::ensure!((1..=1_000_000).contains(&elements), "--elements must be between 1 and 1,000,000, got {elements}");
            print(out, "bench lattice", &crate::fem::bench::bench_lattice(elements)?);
        }
    }
    Ok(())
}
