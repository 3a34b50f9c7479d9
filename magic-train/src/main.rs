//! `magic`: train, evaluate, export and run learned inversions of physical models.

use clap::Parser;

fn main() {
    if let Err(e) = magic_train::cli::run(magic_train::cli::Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
