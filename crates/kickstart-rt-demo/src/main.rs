//! `ksrt`: the kickstart-rt demo, renderer and benchmark tool. It uses only the SDK's public API.

mod gpu;
mod render;
mod scene;

use clap::{Parser, Subcommand};

/// Result of the `ksrt` commands: any error, printed by `main`.
pub type AnyResult<T> = Result<T, Box<dyn std::error::Error>>;

/// kickstart-rt's demo and tool.
#[derive(Parser)]
#[command(
    name = "ksrt",
    version,
    about = "kickstart-rt: ray-traced effects on wgpu — demo and tools"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the adapter, backend, and the features/limits the SDK needs or can use.
    Info,
    /// Render the built-in default scene and write PNG images.
    Render {
        /// Image size, WIDTHxHEIGHT.
        #[arg(long, default_value = "1280x720")]
        size: String,
        /// Output folder.
        #[arg(long, default_value = "out")]
        out: std::path::PathBuf,
    },
}

fn main() {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info => gpu::info(),
        Command::Render { size, out } => gpu::render(&size, out),
    };
    if let Err(e) = result {
        eprintln!("ksrt: {e}");
        std::process::exit(1);
    }
}
