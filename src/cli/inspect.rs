//! `furrow inspect FILE`.

use super::Output;
use std::path::PathBuf;

/// Arguments of `furrow inspect`.
#[derive(Debug, clap::Args)]
pub struct InspectArgs {
    /// The glTF file (.glb or .gltf).
    pub file: PathBuf,
    /// Whether the rig's buffer and image files may lie outside its folder.
    #[command(flatten)]
    pub paths: super::RigPathsArgs,
}

/// Print the summary of one file.
pub fn run(a: InspectArgs, out: &Output) -> anyhow::Result<()> {
    let s = crate::io::inspect::summarize_with(&a.file, a.paths.read())?;
    out.json_result(&serde_json::to_value(&s)?);
    out.say(s.to_string().trim_end());
    Ok(())
}
