//! `furrow rig generate`.

use super::Output;
use crate::io::atomic::{self, Overwrite};
use std::path::PathBuf;

/// `furrow rig …` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum RigCommand {
    /// Generate a procedural rig as a GLB: the face (metres, ~10k vertices, nine named blend
    /// shapes, a weights animation; the default); the capture-shaped head (a whole head of
    /// ~2.6k vertices, the 52 ARKit shapes, an 11 s performance, written compact: quantized,
    /// sparse targets, meshopt-compressed); or a stand-in for a downloaded avatar, whose lip
    /// press, lip roll, blink and viseme_PP fold the skin as real rigs do: `avatar` (a Ready
    /// Player Me–style skinned body, head of ~2k vertices with the 52 ARKit shapes and 15
    /// visemes, eyes and teeth carrying the same targets; float glTF), `avatar-parts` (a
    /// VRoid-style face: one mesh of skin, eyeballs, lash cards and mouth interior primitives;
    /// compact glTF) or `avatar-clip` (the avatar with a 2.5 s clip through the folding shapes).
    #[command(
        after_help = "Example:\n  furrow rig generate -o rigs/face.glb --force\n  furrow rig generate --kind head -o rigs/head.glb --force\n  furrow rig generate --kind avatar -o rigs/avatar.glb --force\n  furrow rig generate --kind avatar-parts -o rigs/avatar_parts.glb --force\n  furrow rig generate --kind avatar-clip -o rigs/avatar_clip.glb --force"
    )]
    Generate {
        /// Which rig: `face` (rigs/face.glb), `head` (rigs/head.glb), `avatar`
        /// (rigs/avatar.glb), `avatar-parts` (rigs/avatar_parts.glb) or `avatar-clip`
        /// (rigs/avatar_clip.glb).
        #[arg(long, value_enum, default_value_t = RigKind::Face)]
        kind: RigKind,
        /// Output path (default rigs/<kind>.glb, with `_` for `-`).
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Replace the output if it exists.
        #[arg(long)]
        force: bool,
    },
}

/// The procedural rigs `furrow rig generate` makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RigKind {
    /// The open face mask of `rigs/face.glb` (float glTF).
    Face,
    /// The capture-shaped whole head of `rigs/head.glb` (compact glTF).
    Head,
    /// The Ready Player Me–style avatar of `rigs/avatar.glb` (float glTF).
    Avatar,
    /// The VRoid-style face of several primitives of `rigs/avatar_parts.glb` (compact glTF).
    AvatarParts,
    /// The avatar with a clip through its folding shapes, `rigs/avatar_clip.glb` (float glTF).
    AvatarClip,
}

impl RigKind {
    /// The default output path of the kind.
    pub fn default_output(self) -> PathBuf {
        PathBuf::from(match self {
            RigKind::Face => "rigs/face.glb",
            RigKind::Head => "rigs/head.glb",
            RigKind::Avatar => "rigs/avatar.glb",
            RigKind::AvatarParts => "rigs/avatar_parts.glb",
            RigKind::AvatarClip => "rigs/avatar_clip.glb",
        })
    }
}

/// A generated rig's parts and bytes, ready to write and describe.
struct Generated {
    mesh: crate::mesh::TriMesh,
    targets: Vec<crate::io::model::MorphTarget>,
    keys: crate::io::model::WeightKeys,
    bytes: Vec<u8>,
}

/// Generate the rig of `kind` and encode it (the face and the avatars with a body as float
/// glTF, the head and the parts face compact).
fn generate(kind: RigKind) -> anyhow::Result<Generated> {
    Ok(match kind {
        RigKind::Face => {
            let rig = crate::rig::face::generate();
            let bytes = crate::io::export::rig_glb("face", &rig.mesh, &rig.targets, &rig.keys)?;
            Generated {
                mesh: rig.mesh,
                targets: rig.targets,
                keys: rig.keys,
                bytes,
            }
        }
        RigKind::Head => {
            let rig = crate::rig::head::generate();
            let bytes = crate::io::compact::rig_glb("head", &rig.mesh, &rig.targets, &rig.keys)?;
            Generated {
                mesh: rig.mesh,
                targets: rig.targets,
                keys: rig.keys,
                bytes,
            }
        }
        RigKind::Avatar | RigKind::AvatarParts | RigKind::AvatarClip => {
            let rig = match kind {
                RigKind::Avatar => crate::rig::avatar::avatar(),
                RigKind::AvatarParts => crate::rig::avatar::avatar_parts(),
                _ => crate::rig::avatar::avatar_clip(),
            };
            let bytes = rig.glb()?;
            Generated {
                mesh: rig.skin,
                targets: rig.targets,
                keys: rig.keys,
                bytes,
            }
        }
    })
}

/// Run a `rig` subcommand.
pub fn run(c: RigCommand, out: &Output) -> anyhow::Result<()> {
    match c {
        RigCommand::Generate {
            kind,
            output,
            force,
        } => {
            let output = output.unwrap_or_else(|| kind.default_output());
            atomic::check_free(&[&output], Overwrite::from_force(force))?;
            let rig = generate(kind)?;
            let bytes = &rig.bytes;
            atomic::write(
                &output,
                bytes,
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
