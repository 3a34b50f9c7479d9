//! The Cortex-M4F firmware from the host: build it with a model embedded, run it under QEMU
//! (`mps2-an386`) with observation lines on its standard input, and read back its result lines
//! and cost figures.
//!
//! The firmware (`magic-firmware`) prints one line per input line (a result or `error,…`), then
//! lines `# key=value` with its measured costs (instructions per inversion, stack high-water mark,
//! flash used, …); see the firmware's README. The QEMU command line is the target runner of the
//! workspace's `.cargo/config.toml`, so `cargo run` and these functions run the board alike.
//!
//! Nothing here installs anything: [`ensure_toolchain`] says what is missing and how to get it.

use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The firmware's target triple.
pub const TARGET: &str = "thumbv7em-none-eabihf";
/// The cargo profile the firmware is built with (size-optimised, fat LTO).
pub const PROFILE: &str = "mcu";
/// The QEMU command used when `.cargo/config.toml` has no runner for [`TARGET`].
pub const DEFAULT_RUNNER: &str = "qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -icount shift=0 -display none -serial none -monitor none -semihosting-config enable=on,target=native -kernel";

/// What one run of the firmware produced.
#[derive(Clone, Debug, Default)]
pub struct FirmwareRun {
    /// Result lines in input order (`x,y,depth,dv,residual,flags,used` or `error,…`), without the
    /// cost lines.
    pub results: Vec<String>,
    /// Every `# key=value` cost line, by key.
    pub costs: BTreeMap<String, String>,
    /// Mean executed instructions per inversion of a complete observation vector.
    pub instructions_per_inversion: Option<u64>,
    /// Instructions of the encoder alone (one observation, mean of repeats).
    pub instructions_encoder: Option<u64>,
    /// Instructions of the forward model (Mogi and effects) alone.
    pub instructions_mogi: Option<u64>,
    /// Instructions of the correction network alone.
    pub instructions_correction: Option<u64>,
    /// Stack high-water mark of the streaming path, bytes.
    pub stack_bytes: Option<u64>,
    /// Flash used (code, constants and the model), bytes.
    pub flash_bytes: Option<u64>,
    /// Process exit code (`None` if killed by a signal).
    pub exit_code: Option<i32>,
    /// Whether the firmware exited with success.
    pub success: bool,
    /// QEMU's standard error (empty on a normal run).
    pub stderr: String,
}

impl FirmwareRun {
    /// A cost figure as an integer.
    pub fn cost(&self, key: &str) -> Option<u64> {
        self.costs.get(key).and_then(|v| v.trim().parse().ok())
    }
}

/// The workspace root (the directory holding `.cargo/config.toml` and `magic-firmware/`).
pub fn workspace_root() -> Result<PathBuf> {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    for dir in here.ancestors() {
        if dir.join("magic-firmware").join("Cargo.toml").is_file() {
            return Ok(dir.to_path_buf());
        }
    }
    bail!(
        "cannot find the workspace root (a directory with magic-firmware/) above {}",
        here.display()
    )
}

/// Checks that `qemu-system-arm` runs and that the Rust target [`TARGET`] is installed; the error
/// says how to install what is missing.
pub fn ensure_toolchain() -> Result<()> {
    let mut missing = Vec::new();
    match Command::new("qemu-system-arm")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
    {
        Ok(s) if s.success() => {}
        _ => missing.push(
            "qemu-system-arm (Debian/Ubuntu: `apt-get install -y qemu-system-arm`)".to_string(),
        ),
    }
    let sysroot = Command::new(rustc())
        .args(["--print", "sysroot"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()));
    let has_target =
        sysroot.is_some_and(|s| s.join("lib/rustlib").join(TARGET).join("lib").is_dir());
    if !has_target {
        missing.push(format!(
            "the Rust target {TARGET} (`rustup target add {TARGET}`)"
        ));
    }
    if !missing.is_empty() {
        bail!("the firmware needs {}", missing.join(" and "));
    }
    Ok(())
}

fn cargo() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".into())
}

fn rustc() -> String {
    std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into())
}

/// Builds started from this process run one after the other: cargo writes the firmware's ELF to
/// the same path whatever the model (and whichever build: see also `qemu_uart`).
pub static BUILD: Mutex<()> = Mutex::new(());

/// The firmware features a model needs: `rtm` for an RTM model (the default firmware links only
/// the Mogi forward model and holds the 49 KiB budget). A file that does not decode gets the
/// default firmware, which reports it (`error,model: …`).
pub fn firmware_features(model: &[u8]) -> Vec<&'static str> {
    match magic_core::Model::decode(model) {
        Ok(m) if matches!(m.problem, magic_core::Problem::Rtm { .. }) => vec!["rtm"],
        _ => vec![],
    }
}

/// Builds the firmware with `model_path` embedded (`cargo build -p magic-firmware --target
/// thumbv7em-none-eabihf --profile mcu`, `MAGIC_MODEL` set, the features of
/// [`firmware_features`]) and returns the path of a copy of the ELF that belongs to this model
/// (so that later builds with other models do not replace it).
pub fn build_firmware(model_path: &Path) -> Result<PathBuf> {
    build_firmware_with(model_path, &[])
}

/// [`build_firmware`] with extra firmware features (e.g. `panic-never`).
pub fn build_firmware_with(model_path: &Path, extra_features: &[&str]) -> Result<PathBuf> {
    let model_path = model_path
        .canonicalize()
        .with_context(|| format!("model file {}", model_path.display()))?;
    let model =
        std::fs::read(&model_path).with_context(|| format!("reading {}", model_path.display()))?;
    check_int8(&model_path, &model)?;
    let root = workspace_root()?;
    let mut features = firmware_features(&model);
    features.extend_from_slice(extra_features);
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let out = Command::new(cargo())
        .current_dir(&root)
        .args([
            "build",
            "-p",
            "magic-firmware",
            "--target",
            TARGET,
            "--profile",
            PROFILE,
        ])
        .args(["--features", &features.join(",")])
        .args(["--message-format", "json-render-diagnostics"])
        .env("MAGIC_MODEL", &model_path)
        .stderr(Stdio::inherit())
        .output()
        .context("running cargo to build the firmware")?;
    if !out.status.success() {
        bail!(
            "building the firmware failed ({}); see the compiler output above",
            out.status
        );
    }
    let elf = artifact_path(&String::from_utf8_lossy(&out.stdout))
        .context("cargo did not report the firmware executable")?;
    // Copy it under a name of its own: the next build (another model) replaces cargo's ELF.
    // Builds from other processes are not serialised with this one: run one at a time.
    let dir = elf.parent().unwrap_or(Path::new(".")).join("by-model");
    std::fs::create_dir_all(&dir)?;
    let key = fnv1a(&[model.as_slice(), features.join(",").as_bytes()].concat());
    let copy = dir.join(format!("magic-firmware-{key:016x}.elf"));
    std::fs::copy(&elf, &copy)
        .with_context(|| format!("copying {} to {}", elf.display(), copy.display()))?;
    Ok(copy)
}

/// Room for the model in the budgeted firmware: memory.x's 49 KiB of flash less the firmware's
/// own code and constants (29 805 bytes: flash 49 512 bytes with the 19 707-byte int8 C of
/// `magic loop`'s Akutan round 2; 29 237 before the dated terms were added after C), with about
/// 900 bytes of margin.
pub const MODEL_ROOM: usize = 19 * 1024;

/// The budgeted firmware (memory.x: 49 KiB of flash, the model included) runs int8 Mogi models:
/// an f32 model (what `magic train` writes, about four times larger than its int8 export) that
/// exceeds [`MODEL_ROOM`] only makes the link fail with "section .rodata will not fit in region
/// FLASH". Says what to do instead, before building. (A file that does not decode is left to
/// the firmware, which reports it; RTM models get the larger `rtm` layout.)
pub fn check_int8(path: &Path, model: &[u8]) -> Result<()> {
    let Ok(m) = magic_core::Model::decode(model) else {
        return Ok(());
    };
    if matches!(m.problem, magic_core::Problem::Rtm { .. }) {
        return Ok(());
    }
    // `magic export` quantises every layer but the encoder's head (B, C); `magic train` writes
    // f32 layers only.
    let layers = m.encoder.len() + m.decoder.len();
    let int8 = m
        .encoder
        .iter()
        .chain(m.decoder.iter())
        .filter(|l| matches!(l.weights, magic_core::nn::Weights::Int8 { .. }))
        .count();
    if layers > 0 && int8 == 0 && model.len() > MODEL_ROOM {
        bail!(
            "{}: an f32 model ({} bytes, no int8 layer: what `magic train` writes); the firmware \
             has room for about {MODEL_ROOM} bytes of model in its 49 KiB flash budget. Export it \
             to int8 first (about four times smaller): \
             `magic export --model {} --out model_int8.magic`, then use model_int8.magic",
            path.display(),
            model.len(),
            path.display()
        );
    }
    Ok(())
}

/// The executable of the `magic-firmware` bin from cargo's JSON messages.
pub fn artifact_path(json_lines: &str) -> Option<PathBuf> {
    json_lines
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["reason"] == "compiler-artifact" && v["target"]["name"] == "magic-firmware")
        .filter_map(|v| v["executable"].as_str().map(PathBuf::from))
        .next_back()
}

fn fnv1a(b: &[u8]) -> u64 {
    b.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &x| {
        (h ^ x as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The QEMU command: the runner of [`TARGET`] in the workspace's `.cargo/config.toml`, else
/// [`DEFAULT_RUNNER`].
pub fn runner() -> Vec<String> {
    let from_config = workspace_root()
        .ok()
        .and_then(|r| std::fs::read_to_string(r.join(".cargo/config.toml")).ok())
        .and_then(|text| {
            let mut in_target = false;
            for line in text.lines().map(str::trim) {
                if line.starts_with('[') {
                    in_target = line == format!("[target.{TARGET}]");
                } else if in_target {
                    if let Some(v) = line
                        .strip_prefix("runner")
                        .map(str::trim_start)
                        .and_then(|l| l.strip_prefix('='))
                    {
                        return Some(v.trim().trim_matches('"').to_string());
                    }
                }
            }
            None
        });
    from_config
        .unwrap_or_else(|| DEFAULT_RUNNER.to_string())
        .split_whitespace()
        .map(String::from)
        .collect()
}

/// Runs the firmware `elf` under QEMU with `input` on its standard input (one observation vector
/// per line), killing it after `timeout_s` seconds (an error). Returns its result lines, its cost
/// figures and its exit status; a firmware failure (bad model, fault) is a run with
/// `success == false`, not an error.
pub fn run_firmware(elf: &Path, input: &str, timeout_s: u64) -> Result<FirmwareRun> {
    let cmd = runner();
    let (prog, args) = cmd.split_first().context("empty QEMU runner command")?;
    let mut child = Command::new(prog)
        .args(args)
        .arg(elf)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| {
            format!("starting {prog} (is QEMU installed? see magic_train::qemu::ensure_toolchain)")
        })?;
    let mut stdin = child.stdin.take().context("QEMU stdin")?;
    let input = input.to_string();
    // Feed and drain on threads so that neither pipe can fill up and block the other.
    let feeder = std::thread::spawn(move || {
        let _ = stdin.write_all(input.as_bytes());
    });
    let mut out_pipe = child.stdout.take().context("QEMU stdout")?;
    let mut err_pipe = child.stderr.take().context("QEMU stderr")?;
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out_pipe.read_to_string(&mut s);
        s
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err_pipe.read_to_string(&mut s);
        s
    });
    let deadline = Instant::now() + Duration::from_secs(timeout_s);
    let status = loop {
        if let Some(s) = child.try_wait()? {
            break s;
        }
        if Instant::now() >= deadline {
            let _ = child.kill();
            let _ = child.wait();
            bail!("the firmware did not finish within {timeout_s} s (killed)");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let _ = feeder.join();
    let stdout = reader.join().unwrap_or_default();
    let stderr = err_reader.join().unwrap_or_default();
    let mut run = parse_output(&stdout);
    run.exit_code = status.code();
    run.success = status.success();
    run.stderr = stderr;
    Ok(run)
}

/// Splits the firmware's standard output into result lines and `# key=value` cost figures.
pub fn parse_output(stdout: &str) -> FirmwareRun {
    let mut run = FirmwareRun::default();
    for line in stdout.lines() {
        if let Some(c) = line.strip_prefix('#') {
            if let Some((k, v)) = c.trim().split_once('=') {
                run.costs.insert(k.trim().to_string(), v.trim().to_string());
            }
        } else {
            run.results.push(line.to_string());
        }
    }
    run.instructions_per_inversion = run.cost("instructions_per_inversion");
    run.instructions_encoder = run.cost("instructions_encoder");
    run.instructions_mogi = run.cost("instructions_mogi");
    run.instructions_correction = run.cost("instructions_correction");
    run.stack_bytes = run.cost("stack_bytes");
    run.flash_bytes = run.cost("flash_bytes");
    run
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_is_split_into_results_and_costs() {
        let run = parse_output("1,2,3\nerror,field 1: not a number\n# magic-firmware cost: x\n# instructions_per_inversion=39000\n# stack_bytes=7000\n");
        assert_eq!(run.results, ["1,2,3", "error,field 1: not a number"]);
        assert_eq!(run.instructions_per_inversion, Some(39000));
        assert_eq!(run.stack_bytes, Some(7000));
        assert_eq!(run.flash_bytes, None);
    }

    #[test]
    fn runner_comes_from_the_cargo_config() {
        let r = runner();
        assert_eq!(r[0], "qemu-system-arm");
        assert_eq!(r.last().map(String::as_str), Some("-kernel"));
        assert!(
            r.iter().any(|a| a == "shift=0"),
            "the instruction counts need -icount shift=0"
        );
    }
}
