//! The deployable firmware (`magic-firmware`, feature `uart`) from the host: build it, run it
//! under QEMU with its UART0 on a local TCP port (what `magic station --port tcp:HOST:PORT`
//! talks to), and check its ELF for semihosting calls.
//!
//! The QEMU command is the one to use by hand as well:
//!
//! ```text
//! qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -accel tcg,thread=single -display none \
//!     -monitor none -serial tcp:127.0.0.1:5555,server=on,wait=on,nodelay=on -kernel magic-firmware.elf
//! ```
//!
//! `server=on,wait=on`: QEMU waits for the station to connect before it starts the board, so the
//! board's start-up line is not lost; `nodelay=on`: the board's answers leave at once instead of
//! waiting for the host's delayed acknowledgement (~40 ms a line otherwise). No `-icount`: the
//! board's clock (upload timeout, watchdog) then follows host time. No `-semihosting`: a
//! semihosting call would stop this firmware with a fault. `-accel tcg,thread=single`: the board
//! has one core; single-threaded TCG moved the UART's bytes as fast or faster here.
//!
//! QEMU's model of the UART takes one byte from the socket per turn of its main loop (the
//! device holds one byte, and QEMU looks again only on its next turn): about 30 µs of host CPU
//! and two thread switches per byte received, measured. The emulated link so carries at most
//! some 30 KB/s (about 150 days of 36 channels a second), less on a loaded host (50–100 days a
//! second measured on 2 cores at a load average of 13). A board at 115 200 baud: 11.5 KB/s.
//!
//! What QEMU keeps across a system reset (SYSRESETREQ, or the watchdog), checked with this
//! firmware: the devices are reset and every loadable segment of the ELF is written again into
//! memory — its flash bytes as in the file, and the RAM of its `.bss` segment zero-filled — so a
//! byte the board wrote inside the program image is undone, while flash and RAM outside the ELF
//! (the model slots, their headers, the reset-cause words) keep what was written. The TCP
//! connection stays open. A new QEMU process starts with all of it zero (an erased board).

use crate::firmware::qemu::{artifact_path, workspace_root, BUILD, PROFILE, TARGET};
use anyhow::{bail, Context, Result};
use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Builds the deployable firmware (`--no-default-features --features uart`, plus `extra`
/// features such as `panic-never` or `hang-command`) and returns a copy of its ELF named for
/// its features (later builds with other features do not replace it).
pub fn build_deployable(extra: &[&str]) -> Result<PathBuf> {
    let root = workspace_root()?;
    let mut features = vec!["uart"];
    features.extend_from_slice(extra);
    let features = features.join(",");
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let out = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .current_dir(&root)
        .args(["build", "-p", "magic-firmware", "--target", TARGET])
        .args(["--profile", PROFILE, "--no-default-features"])
        .args(["--features", &features])
        .args(["--message-format", "json-render-diagnostics"])
        .stderr(Stdio::inherit())
        .output()
        .context("running cargo to build the deployable firmware")?;
    if !out.status.success() {
        bail!(
            "building the deployable firmware (features {features}) failed ({}); see the compiler output above",
            out.status
        );
    }
    let elf = artifact_path(&String::from_utf8_lossy(&out.stdout))
        .context("cargo did not report the firmware executable")?;
    let dir = elf.parent().unwrap_or(Path::new(".")).join("by-model");
    std::fs::create_dir_all(&dir)?;
    let copy = dir.join(format!("magic-firmware-{}.elf", features.replace(',', "+")));
    std::fs::copy(&elf, &copy)
        .with_context(|| format!("copying {} to {}", elf.display(), copy.display()))?;
    Ok(copy)
}

/// How long QEMU may take to say on which port it listens.
const QEMU_START_TIMEOUT: Duration = Duration::from_secs(20);

/// The port of QEMU's `… QEMU waiting for connection on: disconnected:tcp:127.0.0.1:<port>,server=on`.
fn listening_port(line: &str) -> Option<u16> {
    let address = line.split("waiting for connection on:").nth(1)?;
    let after = address.split("tcp:").nth(1)?;
    after
        .split(',')
        .next()?
        .rsplit(':')
        .next()?
        .trim()
        .parse()
        .ok()
}

/// A QEMU `mps2-an386` running a firmware with UART0 on a local TCP port; killed on drop.
pub struct UartQemu {
    child: Child,
    /// The port QEMU listens on (`tcp:127.0.0.1:<port>` for `magic station`).
    pub port: u16,
}

impl UartQemu {
    /// Starts QEMU with `elf` and UART0 on a free local port, waiting until it listens. The board
    /// starts when the first client connects.
    ///
    /// QEMU binds the port itself (port 0: the system's choice) and says which on its standard
    /// error: a port found free here and handed to QEMU could be taken by another process
    /// (another test's QEMU, or the local end of a connection) before QEMU binds it.
    pub fn start(elf: &Path) -> Result<UartQemu> {
        let mut child = Command::new("qemu-system-arm")
            .args(["-machine", "mps2-an386", "-cpu", "cortex-m4"])
            .args(["-accel", "tcg,thread=single"])
            .args(["-display", "none", "-monitor", "none"])
            .args(["-serial", "tcp:127.0.0.1:0,server=on,wait=on,nodelay=on"])
            .arg("-kernel")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .context(
                "starting qemu-system-arm (see magic_train::firmware::qemu::ensure_toolchain)",
            )?;
        let stderr = child.stderr.take().context("QEMU's standard error")?;
        let (tx, rx) = mpsc::channel();
        // Reads QEMU's standard error to its end (so that QEMU never blocks on it), sending the
        // port once it is said, or what QEMU said if it ends first.
        std::thread::spawn(move || {
            let mut said = Vec::new();
            let mut sent = false;
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                if !sent {
                    if let Some(port) = listening_port(&line) {
                        sent = tx.send(Ok(port)).is_ok();
                    } else {
                        said.push(line);
                    }
                }
            }
            if !sent {
                let _ = tx.send(Err(said.join("\n")));
            }
        });
        let mut qemu = UartQemu { child, port: 0 };
        match rx.recv_timeout(QEMU_START_TIMEOUT) {
            Ok(Ok(port)) => {
                qemu.port = port;
                Ok(qemu)
            }
            Ok(Err(said)) => bail!("QEMU ended before listening on a port: {said}"),
            Err(_) => {
                bail!("QEMU did not say on which port it listens within {QEMU_START_TIMEOUT:?}")
            }
        }
    }

    /// `tcp:127.0.0.1:<port>`, the station's `--port`.
    pub fn address(&self) -> String {
        format!("tcp:127.0.0.1:{}", self.port)
    }

    /// Connects to the board's UART, retrying while QEMU starts (up to `timeout`).
    pub fn connect(&mut self, timeout: Duration) -> Result<TcpStream> {
        let deadline = Instant::now() + timeout;
        loop {
            match TcpStream::connect(("127.0.0.1", self.port)) {
                Ok(s) => return Ok(s),
                Err(e) => {
                    if let Some(status) = self.child.try_wait()? {
                        bail!(
                            "QEMU exited ({status}) before listening on port {}",
                            self.port
                        );
                    }
                    if Instant::now() >= deadline {
                        bail!(
                            "QEMU did not listen on port {} within {timeout:?}: {e}",
                            self.port
                        );
                    }
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
        }
    }
}

impl Drop for UartQemu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `llvm-objdump` of the Rust toolchain (`rustup component add llvm-tools`), else one on the
/// `PATH`.
fn objdump() -> Result<PathBuf> {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let info = |arg: &str| -> Option<String> {
        let o = Command::new(&rustc).arg(arg).output().ok()?;
        Some(String::from_utf8_lossy(&o.stdout).into_owned())
    };
    let sysroot = info("--print=sysroot").map(|s| PathBuf::from(s.trim()));
    let host = info("-vV").and_then(|v| {
        v.lines()
            .find_map(|l| l.strip_prefix("host: ").map(|h| h.trim().to_string()))
    });
    if let (Some(sysroot), Some(host)) = (sysroot, host) {
        let p = sysroot
            .join("lib/rustlib")
            .join(host)
            .join("bin/llvm-objdump");
        if p.is_file() {
            return Ok(p);
        }
    }
    if Command::new("llvm-objdump")
        .arg("--version")
        .output()
        .is_ok()
    {
        return Ok(PathBuf::from("llvm-objdump"));
    }
    bail!("llvm-objdump not found: `rustup component add llvm-tools`")
}

/// The semihosting traces in a firmware ELF: every `bkpt 0xab` instruction (the Thumb
/// semihosting trap) in its disassembly, and every symbol of the `cortex_m_semihosting` crate.
/// Empty for a firmware that makes no semihosting call.
pub fn semihosting_calls(elf: &Path) -> Result<Vec<String>> {
    let out = Command::new(objdump()?)
        .args(["-d", "--demangle"])
        .arg(elf)
        .output()
        .with_context(|| format!("disassembling {}", elf.display()))?;
    if !out.status.success() {
        bail!(
            "llvm-objdump failed on {}: {}",
            elf.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut found = Vec::new();
    let mut function = String::new();
    let mut instructions = 0usize;
    for line in text.lines() {
        // Instruction lines: `    1a2b: <bytes> \t<mnemonic> …`.
        if line.starts_with(' ') && line.contains(':') && line.contains('\t') {
            instructions += 1;
        }
        if line.ends_with(">:") {
            function = line.to_string();
            if line.contains("cortex_m_semihosting") {
                found.push(format!("symbol {line}"));
            }
        }
        let l = line.to_ascii_lowercase();
        if l.contains("bkpt") && l.contains("0xab") {
            found.push(format!("{function} {}", line.trim()));
        }
    }
    // The disassembly must have covered the program (an empty one proves nothing).
    if instructions < 1000 {
        bail!(
            "only {instructions} instructions found in {} (is it the firmware ELF?)",
            elf.display()
        );
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_port_is_read_from_qemus_message() {
        let line = "qemu-system-arm: -serial tcp:127.0.0.1:0,server=on,wait=on,nodelay=on: info: \
                    QEMU waiting for connection on: disconnected:tcp:127.0.0.1:33049,server=on";
        assert_eq!(listening_port(line), Some(33049));
        assert_eq!(
            listening_port("qemu-system-arm: -kernel x: No such file"),
            None
        );
    }
}
