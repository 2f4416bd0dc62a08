//! Summaries of glTF files.
