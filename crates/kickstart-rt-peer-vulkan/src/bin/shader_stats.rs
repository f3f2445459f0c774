//! `shader-stats`: how the Vulkan driver compiled our WGSL compute shaders — register count,
//! local memory (spills), shared memory, instruction counts: whatever the driver reports through
//! `VK_KHR_pipeline_executable_properties` — for when no profiler reads Vulkan shaders.
//!
//! ```text
//! shader-stats [--entry NAME]... [--param NAME=VALUE]... [--device N] [--out DIR] [--unchecked]
//!     SHADER [SHADER ...]
//! ```
//!
//! A SHADER ending in `.wgsl` is a file read as it is; any other is a module of the SDK (its path
//! under `crates/kickstart-rt/shaders/` without `.wgsl`), composed with its imports and the
//! `--param` values exactly as the SDK composes its passes (`kickstart_rt::compose_shader`).
//! Files come first, then the composed modules, joined with `"\n"`. E.g. the ray batch pass and
//! the LBVH's climb:
//!
//! ```sh
//! cargo run --release -p kickstart-rt-peer-vulkan --bin shader-stats -- trace/rays
//! cargo run --release -p kickstart-rt-peer-vulkan --bin shader-stats -- \
//!     scene/lbvh/hploc --entry lbvh_climb --out out/stats
//! cargo run --release -p kickstart-rt-peer-vulkan --bin shader-stats -- \
//!     trace/ao --param GBUFFER_GROUP=1 --param OUTPUT0_FORMAT=rgba16float
//! ```
//!
//! The WGSL is parsed and validated by naga 30 and written as SPIR-V the way wgpu 30's Vulkan
//! backend does it for `ShaderRuntimeChecks::checked()` (the default; `--unchecked` for
//! `unchecked()`): one module per entry point (holding only what it reaches), the SPIR-V version
//! of the device's API version, index bounds checks `Restrict`, buffer and image-load checks left
//! to the driver where `robustBufferAccess2` / `robustImageAccess(2)` are enabled (else
//! `Restrict`), loop bounding and integer-division checks on, workgroup memory zero-initialised
//! (natively where the device can). The device gets the features wgpu enables that change code
//! generation (robustness, zero-initialised workgroup memory, subgroup size control, f16, int64
//! atomics; the stage gets `ALLOW_VARYING_SUBGROUP_SIZE` where wgpu's `SUBGROUP` would be
//! there), and the pipeline layout is wgpu's automatic one: the bindings the entry point uses,
//! each group's Vulkan bindings renumbered 0, 1, 2… in WGSL binding order, as wgpu-hal does.
//!
//! For each compute entry point (or each `--entry`), a pipeline is created with
//! `CAPTURE_STATISTICS | CAPTURE_INTERNAL_REPRESENTATIONS` and the tool prints each executable
//! (name, description, subgroup size), every statistic (name, value, format, description) and
//! the internal representations' names and sizes, then a table of the statistics of all entry
//! points. With `--out DIR` each text representation is written to
//! `DIR/<entry>-<executable>-<name>.txt` (binary ones to `.bin`), and each entry point's SPIR-V
//! to `DIR/<entry>.spv` (`spirv-dis` reads it).
//!
//! What drivers report: NVIDIA's (580, H100) gives Register Count, Binary Size, Stack Size,
//! Local Memory Size and Shared Memory Size, and no internal representations. Its Local Memory
//! Size comes as 2^36 + the bytes per thread, so `u64` values of 2^32 or more are printed in hex
//! with their low 32 bits. Mesa's lavapipe (22.3, 25.0) does not offer the extension.
//!
//! Device: the first discrete or integrated GPU, else the first device (lavapipe is a CPU
//! device); `--device N` picks by the index printed. A device without the extension gets one
//! line saying so; the pipelines are still created, as a check that the driver accepts them,
//! and the exit status is 0. WGSL errors name the file and line and exit with status 1; usage
//! errors with 2.

#[path = "shader_stats/compile.rs"]
mod compile;
#[path = "shader_stats/vulkan.rs"]
mod vulkan;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use compile::{EntryModule, Source};
use vulkan::{api_string, default_device, Compiled, Gpu, StatValue, Vk};

const USAGE: &str = "\
usage: shader-stats [--entry NAME]... [--param NAME=VALUE]... [--device N] [--out DIR] [--unchecked]
                    SHADER [SHADER ...]

Compiles the WGSL compute entry points of the SHADERs (a SHADER ending in .wgsl is a file; any
other is a module of the SDK, e.g. trace/rays, composed with its imports and the --param values
as the SDK does; files first, joined with \"\\n\") to SPIR-V as wgpu 30 does, creates Vulkan compute pipelines with statistics capture, and prints
what the driver reports through VK_KHR_pipeline_executable_properties.

  --entry NAME   only this compute entry point (repeatable; default: all of them)
  --param N=V    a parameter of the SDK's modules (repeatable), e.g. OUTPUT0_FORMAT=r32float
  --device N     the Vulkan physical device of index N (default: the first discrete or
                 integrated GPU, else device 0)
  --out DIR      write internal representations (<entry>-<n>-<name>.txt, .bin when binary)
                 and each entry point's SPIR-V (<entry>.spv) to DIR
  --unchecked    SPIR-V as for ShaderRuntimeChecks::unchecked() (no bounds checks, no loop
                 bounding, no integer-division checks)
  -h, --help     this text";

/// Command line.
#[derive(Debug, Default, PartialEq)]
struct Args {
    entries: Vec<String>,
    device: Option<usize>,
    out: Option<PathBuf>,
    unchecked: bool,
    /// `--param NAME=VALUE` of the composed modules.
    params: Vec<(String, String)>,
    files: Vec<String>,
}

/// Why the command line was not accepted: `Ok(())` inside means `--help`.
fn parse_args(argv: &[String]) -> Result<Args, Result<(), String>> {
    let mut args = Args::default();
    let mut i = 0;
    let value = |i: &mut usize, flag: &str, inline: Option<&str>| -> Result<String, String> {
        if let Some(v) = inline {
            return Ok(v.to_string());
        }
        *i += 1;
        argv.get(*i)
            .cloned()
            .ok_or_else(|| format!("{flag} needs a value"))
    };
    let mut only_files = false;
    while i < argv.len() {
        let a = argv[i].as_str();
        if only_files || !a.starts_with('-') || a == "-" {
            args.files.push(a.to_string());
            i += 1;
            continue;
        }
        let (flag, inline) = match a.split_once('=') {
            Some((f, v)) if f.starts_with("--") => (f, Some(v)),
            _ => (a, None),
        };
        match flag {
            "--" => only_files = true,
            "-h" | "--help" => return Err(Ok(())),
            "--entry" => args.entries.push(value(&mut i, flag, inline).map_err(Err)?),
            "--device" => {
                let v = value(&mut i, flag, inline).map_err(Err)?;
                args.device = Some(
                    v.parse()
                        .map_err(|_| Err(format!("--device wants a device index, not `{v}`")))?,
                );
            }
            "--out" => args.out = Some(value(&mut i, flag, inline).map_err(Err)?.into()),
            "--unchecked" if inline.is_none() => args.unchecked = true,
            "--param" => {
                let v = value(&mut i, flag, inline).map_err(Err)?;
                let Some((name, value)) = v.split_once('=') else {
                    return Err(Err(format!("--param wants NAME=VALUE, not `{v}`")));
                };
                args.params.push((name.to_string(), value.to_string()));
            }
            _ => return Err(Err(format!("unknown option `{a}`"))),
        }
        i += 1;
    }
    if args.files.is_empty() {
        return Err(Err("no WGSL file or module given".to_string()));
    }
    Ok(args)
}

/// `s` with every character outside `[A-Za-z0-9._-]` replaced by `_`.
fn sanitize(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// A statistic's value and format name. A `u64` of 2^32 or more is shown in hex with its low 32
/// bits: NVIDIA's driver (580, H100) reports "Local Memory Size" as 2^36 + the byte count.
fn format_value(v: StatValue) -> (String, &'static str) {
    match v {
        StatValue::Bool(b) => (b.to_string(), "bool"),
        StatValue::I64(x) => (x.to_string(), "i64"),
        StatValue::U64(x) if x > u64::from(u32::MAX) => (
            format!("0x{x:x} (low 32 bits: {})", x & u64::from(u32::MAX)),
            "u64",
        ),
        StatValue::U64(x) => (x.to_string(), "u64"),
        StatValue::F64(x) => (format!("{x}"), "f64"),
        StatValue::Unknown(f, bits) => (format!("0x{bits:x}"), if f < 0 { "?" } else { "raw" }),
    }
}

/// A value for the table: as [`format_value`], but a `u64` of 2^32 or more shows its low 32 bits
/// and a `*` (the table's footnote says so; the listing above it has the raw value).
fn table_value(v: StatValue) -> String {
    match v {
        StatValue::U64(x) if x > u64::from(u32::MAX) => format!("{}*", x & u64::from(u32::MAX)),
        v => format_value(v).0,
    }
}

/// Everything that ends the run with a message: status 1.
struct Failure(String);

impl From<String> for Failure {
    fn from(s: String) -> Self {
        Failure(s)
    }
}

fn main() -> ExitCode {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let args = match parse_args(&argv) {
        Ok(a) => a,
        Err(Ok(())) => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(Err(e)) => {
            eprintln!("shader-stats: {e}\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure(e)) => {
            eprintln!("shader-stats: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<(), Failure> {
    // WGSL → naga IR, entry points and layouts, all before Vulkan: shader errors need no GPU.
    let source = load_source(args)?;
    let (module, info) = compile::parse_and_validate(&source)
        .map_err(|e| format!("{}: {e}", args.files.join(" + ")))?;
    let names = entry_names(args, &module)?;
    let mut entries = Vec::with_capacity(names.len());
    for n in &names {
        entries.push(compile::prepare_entry(&module, &info, n).map_err(|e| e.0)?);
    }

    // Vulkan.
    let vk = Vk::load()?;
    let chosen = pick_device(args, &vk)?;
    let gpu = vk.open(chosen)?;
    let t = &gpu.target;
    print_code_generation(args, &gpu);
    if let Some(why) = &gpu.unsupported {
        println!(
            "shader-stats: {why}: no statistics on this device; compiling the pipelines only, as \
             a check that the driver accepts them."
        );
    }
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }

    let mut table: Vec<(String, Compiled)> = Vec::new();
    for (entry, m, i) in &entries {
        let spirv = compile::write_spirv(entry, m, i, t, !args.unchecked).map_err(|e| e.0)?;
        println!();
        print_entry_header(entry, spirv.len());
        if let Some(dir) = &args.out {
            let path = dir.join(format!("{}.spv", sanitize(&entry.name)));
            let bytes: Vec<u8> = spirv.iter().flat_map(|w| w.to_le_bytes()).collect();
            write_file(&path, &bytes)?;
            println!("  SPIR-V -> {}", path.display());
        }
        let compiled = gpu
            .compile(entry, &spirv)
            .map_err(|e| format!("entry point `{}`: {e}", entry.name))?;
        print_compiled(entry, &compiled, args.out.as_deref())?;
        table.push((entry.name.clone(), compiled));
    }
    print_table(&table);
    Ok(())
}

/// The WGSL of the arguments: the `.wgsl` files, then the SDK modules composed with the
/// parameters.
fn load_source(args: &Args) -> Result<Source, Failure> {
    let mut parts = Vec::with_capacity(args.files.len());
    let (files, modules): (Vec<&String>, Vec<&String>) =
        args.files.iter().partition(|f| f.ends_with(".wgsl"));
    for f in files {
        let text = std::fs::read_to_string(f).map_err(|e| format!("cannot read {f}: {e}"))?;
        parts.push((f.clone(), text));
    }
    if !modules.is_empty() {
        let roots: Vec<&str> = modules.iter().map(|m| m.as_str()).collect();
        let params: Vec<(&str, &str)> = args
            .params
            .iter()
            .map(|(n, v)| (n.as_str(), v.as_str()))
            .collect();
        let text = kickstart_rt::compose_shader(&roots, &params)
            .map_err(|e| format!("{}: {e}", roots.join(" + ")))?;
        parts.push((roots.join(" + "), text));
    }
    Ok(Source::concat(&parts))
}

/// The entry points to compile: those asked for (each a compute entry point of `module`), or
/// every compute entry point.
fn entry_names(args: &Args, module: &naga::Module) -> Result<Vec<String>, Failure> {
    let available = compile::compute_entry_points(module);
    if args.entries.is_empty() {
        if available.is_empty() {
            return Err(Failure(format!(
                "{}: no compute entry point",
                args.files.join(" + ")
            )));
        }
        return Ok(available);
    }
    for e in &args.entries {
        if !available.contains(e) {
            let other = module.entry_points.iter().find(|ep| &ep.name == e);
            return Err(Failure(match other {
                Some(ep) => format!(
                    "entry point `{e}` is a {:?} entry point; only compute ones are compiled",
                    ep.stage
                ),
                None => format!(
                    "no entry point `{e}` in {}; compute entry points: {}",
                    args.files.join(" + "),
                    available.join(", ")
                ),
            }));
        }
    }
    Ok(args.entries.clone())
}

/// The device of `--device` (or the default one), after listing every device and describing
/// the chosen one.
fn pick_device(args: &Args, vk: &Vk) -> Result<usize, Failure> {
    if vk.devices.is_empty() {
        return Err(Failure("no Vulkan physical device".to_string()));
    }
    let chosen = match args.device {
        Some(n) if n >= vk.devices.len() => {
            return Err(Failure(format!(
                "--device {n}: there are {} devices (0..{})",
                vk.devices.len(),
                vk.devices.len() - 1
            )))
        }
        Some(n) => n,
        None => default_device(&vk.devices),
    };
    for (k, d) in vk.devices.iter().enumerate() {
        println!(
            "{} device {k}: {} ({}, vendor 0x{:04x}, device 0x{:04x})",
            if k == chosen { "*" } else { " " },
            d.name,
            d.kind_name(),
            d.vendor_id,
            d.device_id
        );
    }
    let d = &vk.devices[chosen];
    println!(
        "device {chosen}: {}: Vulkan {}, driver {} {} (version {})",
        d.name,
        api_string(d.api_version),
        d.driver_name,
        d.driver_info,
        d.driver_version_string()
    );
    Ok(chosen)
}

/// Prints what shapes the code the driver gets: the features enabled, the stage flags and the
/// SPIR-V writer's options.
fn print_code_generation(args: &Args, gpu: &Gpu<'_>) {
    let t = &gpu.target;
    let (major, minor) = compile::spirv_version(t.api_version);
    println!(
        "enabled: {}; stage flags: {}",
        gpu.enabled.join(", "),
        if gpu.allow_varying_subgroup_size {
            "ALLOW_VARYING_SUBGROUP_SIZE"
        } else {
            "none"
        }
    );
    let opts = compile::spv_options(t, !args.unchecked, &compile::Layout::default());
    println!(
        "SPIR-V {major}.{minor} by naga 30 as wgpu 30 ({}): bounds checks index {:?}, buffer {:?}, \
         image load {:?}; loop bounding {}; int division checks {}; workgroup zero-init {:?}",
        if args.unchecked {
            "ShaderRuntimeChecks::unchecked()"
        } else {
            "ShaderRuntimeChecks::checked()"
        },
        opts.bounds_check_policies.index,
        opts.bounds_check_policies.buffer,
        opts.bounds_check_policies.image_load,
        if opts.force_loop_bounding { "on" } else { "off" },
        if opts.emit_int_div_checks { "on" } else { "off" },
        opts.zero_initialize_workgroup_memory,
    );
}

fn write_file(path: &Path, data: &[u8]) -> Result<(), Failure> {
    std::fs::write(path, data).map_err(|e| Failure(format!("cannot write {}: {e}", path.display())))
}

fn print_entry_header(entry: &EntryModule, words: usize) {
    let [x, y, z] = entry.workgroup_size;
    println!(
        "== {} (@workgroup_size({x}, {y}, {z}); var<workgroup> {} bytes; SPIR-V {} words)",
        entry.name, entry.workgroup_bytes, words
    );
    let mut groups: BTreeMap<u32, Vec<String>> = BTreeMap::new();
    for b in &entry.layout.bindings {
        let vk = if b.vk_binding == b.binding {
            String::new()
        } else {
            format!(" (vk {})", b.vk_binding)
        };
        let count = if b.count == 1 {
            String::new()
        } else {
            format!("[{}]", b.count)
        };
        groups
            .entry(b.group)
            .or_default()
            .push(format!("{}{vk} {}{count} {}", b.binding, b.name, b.kind));
    }
    for (g, bs) in groups {
        println!("  @group({g}): {}", bs.join(", "));
    }
    if entry.layout.push_constant_size > 0 {
        println!(
            "  push constants: {} bytes",
            entry.layout.push_constant_size
        );
    }
}

fn print_compiled(entry: &EntryModule, c: &Compiled, out: Option<&Path>) -> Result<(), Failure> {
    println!("  vkCreateComputePipelines: {:.1} ms", c.millis);
    for (n, e) in c.executables.iter().enumerate() {
        println!(
            "  executable {n}: {} — {} (stages {:?}, subgroup size {})",
            e.name, e.description, e.stages, e.subgroup_size
        );
        let width = e.stats.iter().map(|s| s.name.len()).max().unwrap_or(0);
        let vwidth = e
            .stats
            .iter()
            .map(|s| format_value(s.value).0.len())
            .max()
            .unwrap_or(0);
        for s in &e.stats {
            let (v, f) = format_value(s.value);
            println!(
                "    {:width$}  {v:>vwidth$} ({f})  {}",
                s.name, s.description
            );
        }
        let mut used = Vec::new();
        for r in &e.reprs {
            let kind = if r.is_text { "text" } else { "binary" };
            let mut line = format!(
                "    representation {}: {} bytes of {kind} — {}",
                r.name,
                r.data.len(),
                r.description
            );
            if let Some(dir) = out {
                let ext = if r.is_text { "txt" } else { "bin" };
                let mut file = sanitize(&format!("{}-{n}-{}", entry.name, r.name));
                if used.contains(&file) {
                    file = format!("{file}-{}", used.len());
                }
                used.push(file.clone());
                let path = dir.join(format!("{file}.{ext}"));
                write_file(&path, &r.data)?;
                line += &format!(" -> {}", path.display());
            }
            println!("{line}");
        }
    }
    Ok(())
}

/// Every statistic of every entry point side by side (first executable of each; more are
/// suffixed with their index).
fn print_table(table: &[(String, Compiled)]) {
    let mut rows: Vec<String> = Vec::new();
    let mut cells: BTreeMap<(String, usize), String> = BTreeMap::new();
    for (col, (_, c)) in table.iter().enumerate() {
        for (n, e) in c.executables.iter().enumerate() {
            for s in &e.stats {
                let row = if n == 0 {
                    s.name.clone()
                } else {
                    format!("{} [{n}]", s.name)
                };
                if !rows.contains(&row) {
                    rows.push(row.clone());
                }
                cells.insert((row, col), table_value(s.value));
            }
        }
    }
    if rows.is_empty() || table.len() < 2 {
        return;
    }
    let w0 = rows.iter().map(|r| r.len()).max().unwrap_or(0);
    let widths: Vec<usize> = table
        .iter()
        .enumerate()
        .map(|(col, (name, _))| {
            rows.iter()
                .filter_map(|r| cells.get(&(r.clone(), col)))
                .map(|v| v.len())
                .chain([name.len()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    println!();
    let mut header = format!("{:w0$}", "statistic");
    for ((name, _), w) in table.iter().zip(&widths) {
        header += &format!("  {name:>w$}");
    }
    println!("{header}");
    for r in &rows {
        let mut line = format!("{r:w0$}");
        for (col, w) in widths.iter().enumerate() {
            let v = cells.get(&(r.clone(), col)).map_or("-", |s| s.as_str());
            line += &format!("  {v:>w$}");
        }
        println!("{line}");
    }
    if cells.values().any(|v| v.ends_with('*')) {
        println!("* the low 32 bits of a value of 2^32 or more (the raw value is listed above)");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn argv(s: &[&str]) -> Vec<String> {
        s.iter().map(|a| a.to_string()).collect()
    }

    #[test]
    fn parses_the_command_line() {
        let a = parse_args(&argv(&[
            "--entry",
            "main",
            "a.wgsl",
            "--entry=other",
            "--device",
            "1",
            "--out=o",
            "--unchecked",
            "--param",
            "A=1",
            "--param=B=rgba16float",
            "b.wgsl",
        ]))
        .expect("valid");
        assert_eq!(
            a,
            Args {
                entries: argv(&["main", "other"]),
                device: Some(1),
                out: Some("o".into()),
                unchecked: true,
                params: vec![("A".into(), "1".into()), ("B".into(), "rgba16float".into())],
                files: argv(&["a.wgsl", "b.wgsl"]),
            }
        );
        assert!(matches!(parse_args(&argv(&["--help"])), Err(Ok(()))));
        assert!(matches!(parse_args(&argv(&[])), Err(Err(_))));
        assert!(matches!(
            parse_args(&argv(&["--device", "x", "a"])),
            Err(Err(_))
        ));
        assert!(matches!(
            parse_args(&argv(&["a.wgsl", "--entry"])),
            Err(Err(_))
        ));
        assert!(matches!(parse_args(&argv(&["--bogus", "a"])), Err(Err(_))));
    }

    #[test]
    fn formats_values() {
        assert_eq!(format_value(StatValue::U64(72)), ("72".to_string(), "u64"));
        assert_eq!(
            format_value(StatValue::U64((1 << 36) + 1024)),
            ("0x1000000400 (low 32 bits: 1024)".to_string(), "u64")
        );
        assert_eq!(table_value(StatValue::U64((1 << 36) + 512)), "512*");
        assert_eq!(table_value(StatValue::U64(512)), "512");
        assert_eq!(
            format_value(StatValue::Bool(true)),
            ("true".to_string(), "bool")
        );
        assert_eq!(
            format_value(StatValue::F64(0.5)),
            ("0.5".to_string(), "f64")
        );
    }

    #[test]
    fn sanitizes_file_names() {
        assert_eq!(sanitize("main-0-NIR (final)/x.y"), "main-0-NIR__final__x.y");
    }
}
