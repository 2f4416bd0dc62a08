//! The `furrow` command: a thin wrapper over [`furrow::cli`].

fn main() {
    std::process::exit(furrow::cli::main());
}
