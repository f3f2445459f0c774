//! `ksrt`: the kickstart-rt demo, renderer and benchmark tool. It uses only the SDK's public API.

mod gpu;

use clap::{Parser, Subcommand};

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
    /// Register the built-in scene's geometry with the SDK and report what it holds
    /// (the image output arrives with the ray tracing core).
    Render,
}

fn main() {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info => gpu::info(),
        Command::Render => gpu::render(),
    };
    if let Err(e) = result {
        eprintln!("ksrt: {e}");
        std::process::exit(1);
    }
}
