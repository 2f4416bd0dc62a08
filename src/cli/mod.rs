//! The command-line interface (clap).
