//! `furrow rig generate`.

use super::Output;
use crate::io::atomic::{self, Overwrite};
use std::path::PathBuf;

/// `furrow rig …` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum RigCommand {
    /// Generate the procedural face rig (metres, ~10k vertices, named blend shapes, a weights
    /// animation) as a GLB.
    #[command(after_help = "Example:\n  furrow rig generate -o rigs/face.glb --force")]
    Generate {
        /// Output path.
        #[arg(short, long, default_value = "rigs/face.glb")]
        output: PathBuf,
        /// Replace the output if it exists.
        #[arg(long)]
        force: bool,
    },
}

/// Run a `rig` subcommand.
pub fn run(c: RigCommand, out: &Output) -> anyhow::Result<()> {
    match c {
        RigCommand::Generate { output, force } => {
            atomic::check_free(&[&output], Overwrite::from_force(force))?;
            let rig = crate::rig::face::generate();
            let bytes = crate::io::export::rig_glb("face", &rig.mesh, &rig.targets, &rig.keys)?;
            atomic::write(
                &output,
                &bytes,
                if force {
                    Overwrite::Replace
                } else {
                    Overwrite::Refuse
                },
            )?;
            let duration = rig.keys.times.last().copied().unwrap_or(0.0);
            out.json_result(&serde_json::json!({
                "ok": true, "output": output, "vertices": rig.mesh.vertex_count(),
                "triangles": rig.mesh.triangle_count(), "targets": rig.targets.iter().map(|t| &t.name).collect::<Vec<_>>(),
                "duration_s": duration,
            }));
            out.say(format!(
                "wrote {}: {} vertices, {} triangles, {} blend shapes ({}), {:.1} s animation",
                output.display(),
                rig.mesh.vertex_count(),
                rig.mesh.triangle_count(),
                rig.targets.len(),
                rig.targets
                    .iter()
                    .map(|t| t.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                duration
            ));
            Ok(())
        }
    }
}
