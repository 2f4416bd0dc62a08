//! How results reach the user: plain text, nothing (`--quiet`), or JSON (`--json`), and
//! progress bars only on an interactive terminal.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::{IsTerminal, Write};

/// Output settings of one run.
#[derive(Debug, Clone, Copy)]
pub struct Output {
    /// No text at all except errors.
    pub quiet: bool,
    /// Machine-readable JSON on stdout instead of text.
    pub json: bool,
}

impl Output {
    /// Settings from the global flags.
    pub fn new(quiet: bool, json: bool) -> Self {
        Self { quiet, json }
    }

    /// Print a line of human text (not in quiet or JSON mode).
    pub fn say(&self, msg: impl AsRef<str>) {
        if !self.quiet && !self.json {
            // A closed pipe (`furrow inspect … | head`) is not an error worth a panic.
            let _ = writeln!(std::io::stdout(), "{}", msg.as_ref());
        }
    }

    /// Print a note to stderr (not in quiet mode): choices furrow made for the user.
    pub fn note(&self, msg: impl AsRef<str>) {
        if !self.quiet {
            eprintln!("{}", msg.as_ref());
        }
    }

    /// Print the JSON result (in JSON mode).
    pub fn json_result(&self, v: &serde_json::Value) {
        if self.json {
            let _ = writeln!(std::io::stdout(), "{}", serde_json::to_string_pretty(v).expect("JSON serialises"));
        }
    }

    /// A progress bar of `len` steps, hidden unless stderr is a terminal and output is text.
    pub fn progress(&self, len: u64, what: &str) -> ProgressBar {
        if self.quiet || self.json || !std::io::stderr().is_terminal() {
            return ProgressBar::hidden();
        }
        let pb = ProgressBar::new(len);
        pb.set_style(
            ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        pb.set_message(what.to_string());
        pb
    }
}
