//! The command line: options, dispatch, exit codes and error reporting.

use crate::cmd;
use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use std::io::Write;
use std::process::ExitCode;

const AFTER_HELP: &str = "\
Examples:
  hostas demo                                   render the built-in scene to hostas-demo.png
  hostas build bunny.obj -o bunny.hostas        build and serialize an acceleration structure
  hostas build a.obj b.ply --compact -o ab.hostas   two BLASes under one TLAS, compacted
  hostas info bunny.hostas                      header and statistics (--json for scripts)
  hostas render bunny.obj -o bunny.png          render a mesh (or a build file) to PNG
  hostas trace bunny.hostas --rays r.bin --hits h.bin   batch-trace binary ray records
  hostas bench                                  build/trace/copy table on built-in scenes
                                                and ../shared/meshes/ when present

Exit status: 0 on success, 1 when the command failed (unreadable, corrupt or invalid input,
failed build, I/O error), 2 on a usage error. Errors are reported on stderr.";

/// Vulkan host acceleration-structure commands on the CPU: build, inspect, render, trace
/// and benchmark acceleration structures.
#[derive(Parser, Debug)]
#[command(name = "hostas", version, about, long_about = None, after_help = AFTER_HELP, propagate_version = true)]
pub struct Cli {
    #[command(flatten)]
    pub global: Global,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Args, Debug, Clone)]
pub struct Global {
    /// Worker threads for builds and tracing (default: all cores)
    #[arg(long, short = 'j', global = true, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub threads: Option<u32>,
    /// No progress bars or informational messages on stderr (reports on stdout stay)
    #[arg(long, short, global = true)]
    pub quiet: bool,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    Demo(cmd::demo::DemoArgs),
    Build(cmd::build::BuildArgs),
    Info(cmd::info::InfoArgs),
    Render(cmd::render::RenderArgs),
    Trace(cmd::trace::TraceArgs),
    Bench(cmd::bench::BenchArgs),
}

/// Build presets, as `VkBuildAccelerationStructureFlagsKHR`.
#[derive(Args, Debug, Clone, Default)]
pub struct PresetArgs {
    /// PREFER_FAST_TRACE: binned SAH, best trace speed
    #[arg(long, conflicts_with = "fast_build")]
    pub fast_trace: bool,
    /// PREFER_FAST_BUILD: Morton-code builder
    #[arg(long)]
    pub fast_build: bool,
    /// LOW_MEMORY: larger leaves, smaller structure
    #[arg(long)]
    pub low_memory: bool,
    /// ALLOW_COMPACTION, and compact before writing
    #[arg(long)]
    pub compact: bool,
    /// ALLOW_UPDATE: the structure may be refitted later
    #[arg(long)]
    pub allow_update: bool,
}

impl PresetArgs {
    pub fn flags(&self) -> hostas::vk::BuildAccelerationStructureFlagsKHR {
        use hostas::vk::BuildAccelerationStructureFlagsKHR as F;
        let mut f = F::empty();
        for (on, flag) in [
            (self.fast_trace, F::PREFER_FAST_TRACE),
            (self.fast_build, F::PREFER_FAST_BUILD),
            (self.low_memory, F::LOW_MEMORY),
            (self.compact, F::ALLOW_COMPACTION),
            (self.allow_update, F::ALLOW_UPDATE),
        ] {
            if on {
                f |= flag;
            }
        }
        f
    }
}

/// Parses `x,y,z`.
pub fn parse_vec3(s: &str) -> std::result::Result<[f32; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected three comma-separated numbers like 1,2.5,-3, got {s:?}"
        ));
    }
    let mut out = [0.0; 3];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p.parse::<f32>().map_err(|e| format!("{p:?}: {e}"))?;
        if !o.is_finite() {
            return Err(format!("{p:?} is not a finite number"));
        }
    }
    Ok(out)
}

/// Writes `s` to stdout; a closed pipe (`hostas info x | head`) is not an error.
pub fn print(s: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(s.as_bytes()).and_then(|_| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => r.context("writing to stdout"),
    }
}

/// Writes a file, naming it in the error.
pub fn write_file(path: &std::path::Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("{}: cannot write", path.display()))
}

pub fn run(cli: Cli) -> Result<()> {
    crate::progress::set_quiet(cli.global.quiet);
    if let Some(n) = cli.global.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n as usize)
            .build_global()
            .context("setting up the thread pool")?;
    }
    match cli.command {
        Command::Demo(a) => cmd::demo::run(a),
        Command::Build(a) => cmd::build::run(a),
        Command::Info(a) => cmd::info::run(a),
        Command::Render(a) => cmd::render::run(a),
        Command::Trace(a) => cmd::trace::run(a),
        Command::Bench(a) => cmd::bench::run(a),
    }
}

/// The `hostas` program.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hostas: error: {e:#}");
            ExitCode::from(1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn vec3() {
        assert_eq!(parse_vec3("1, 2.5,-3"), Ok([1.0, 2.5, -3.0]));
        assert!(parse_vec3("1,2").is_err());
        assert!(parse_vec3("1,2,inf").is_err());
    }
}
