//! Output files written safely: to a temporary name in the same folder, then renamed, so a
//! killed run never leaves a partial file, and an existing file is only replaced on request.

use std::io::Write;
use std::path::{Path, PathBuf};

/// How to treat an output path that already exists.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Overwrite {
    /// Refuse with an error that says to pass `--force`.
    Refuse,
    /// Replace the existing file (atomically).
    Replace,
}

impl Overwrite {
    /// `Replace` when the user passed `--force`, else `Refuse`.
    pub fn from_force(force: bool) -> Self {
        if force {
            Overwrite::Replace
        } else {
            Overwrite::Refuse
        }
    }
}

/// With `Refuse`, fail (naming the file and `--force`) when any of `paths` exists: called
/// before long work, so that a run never ends in a refusal after minutes of simulation.
pub fn check_free<P: AsRef<Path>>(paths: &[P], overwrite: Overwrite) -> anyhow::Result<()> {
    if overwrite == Overwrite::Refuse {
        if let Some(p) = paths.iter().map(|p| p.as_ref()).find(|p| p.exists()) {
            anyhow::bail!(
                "{}: already exists; furrow does not overwrite files unless told to (pass --force)",
                p.display()
            );
        }
    }
    Ok(())
}

/// Write `bytes` to `path` atomically (temporary file + rename). Parent folders are created.
pub fn write(path: &Path, bytes: &[u8], overwrite: Overwrite) -> anyhow::Result<()> {
    check_free(&[path], overwrite)?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir)
        .map_err(|e| anyhow::anyhow!("{}: cannot create folder: {e}", dir.display()))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        anyhow::bail!("{}: cannot write: {e}", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_refuses_and_replaces() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("sub/a.bin");
        write(&p, b"one", Overwrite::Refuse).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"one");
        let e = write(&p, b"two", Overwrite::Refuse)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--force"), "{e}");
        assert_eq!(std::fs::read(&p).unwrap(), b"one");
        write(&p, b"two", Overwrite::Replace).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let leftovers: Vec<_> = std::fs::read_dir(p.parent().unwrap()).unwrap().collect();
        assert_eq!(leftovers.len(), 1);
    }
}
