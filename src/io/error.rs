//! Errors of glTF input and output: each names the file and what is wrong with it.

use std::path::{Path, PathBuf};

/// A glTF file furrow cannot read or write, with the path and a message a user can act on.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", path.display())]
pub struct GltfError {
    /// The file concerned.
    pub path: PathBuf,
    /// What is wrong, in words a user can act on.
    pub message: String,
}

impl GltfError {
    /// An error about `path`.
    pub fn new(path: &Path, message: impl Into<String>) -> Self {
        Self { path: path.to_path_buf(), message: message.into() }
    }
}

/// Shorthand result for glTF input and output.
pub type GltfResult<T> = Result<T, GltfError>;
