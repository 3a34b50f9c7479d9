//! Build script of the firmware.
//!
//! For the bare-metal target (`target_os = "none"`) it
//! * puts the memory layout on the linker search path as `memory.x` — `memory.x` (the measuring
//!   build), `memory-rtm.x` (feature `rtm`), `memory-uart.x` (the deployable build, feature
//!   `uart`) or, with the feature `sd`, `memory-sd.x` / `memory-uart-sd.x` — with an empty
//!   `device.x`, and links with cortex-m-rt's `link.x`;
//! * for the measuring build, embeds the model file named by the environment variable
//!   `MAGIC_MODEL` (copied into `OUT_DIR` as `model.magic`, read by `include_bytes!`). A relative
//!   path is taken from the workspace root. Without `MAGIC_MODEL` the build fails with a message
//!   saying how to set it. The deployable build embeds no model (they are uploaded).
//!
//! For the host it does nothing: there the crate is a stub (`fn main() {}`).

use std::env;
use std::fs;
use std::path::PathBuf;
use std::process::exit;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=MAGIC_MODEL");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let manifest =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));

    // The budgeted Mogi firmware links with memory.x; with the `rtm` feature (RTM models and
    // their tables) with memory-rtm.x; the deployable build (`uart`: code, two model slots and
    // their header pages) with memory-uart.x.
    let uart = env::var_os("CARGO_FEATURE_UART").is_some();
    let layout = if env::var_os("CARGO_FEATURE_RTM").is_some() {
        "memory-rtm.x"
    } else if env::var_os("CARGO_FEATURE_SD").is_some() {
        if uart {
            "memory-uart-sd.x"
        } else {
            "memory-sd.x"
        }
    } else if uart {
        "memory-uart.x"
    } else {
        "memory.x"
    };
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=memory-rtm.x");
    println!("cargo:rerun-if-changed=memory-sd.x");
    println!("cargo:rerun-if-changed=memory-uart.x");
    println!("cargo:rerun-if-changed=memory-uart-sd.x");
    if let Err(e) = fs::copy(manifest.join(layout), out.join("memory.x")) {
        fail(&format!(
            "cannot copy {layout} into OUT_DIR as memory.x: {e}"
        ));
    }
    // cortex-m-rt's `device` feature includes `device.x` (interrupt handler names of a device
    // crate); the firmware has none (its one-entry interrupt table is in `src/rt.rs`).
    if let Err(e) = fs::write(out.join("device.x"), "/* no device interrupts */\n") {
        fail(&format!("cannot write device.x into OUT_DIR: {e}"));
    }
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg=-Tlink.x");
    if uart {
        return;
    }

    let Some(model) = env::var_os("MAGIC_MODEL") else {
        fail(
            "MAGIC_MODEL is not set. The firmware embeds a model file: build it with\n  \
             MAGIC_MODEL=path/to/model.magic cargo build -p magic-firmware --target thumbv7em-none-eabihf --profile mcu\n\
             (make a model with `magic export`; a relative path is taken from the workspace root).",
        );
    };
    let mut path = PathBuf::from(&model);
    if path.is_relative() {
        path = manifest.join("..").join(path);
    }
    println!("cargo:rerun-if-changed={}", path.display());
    match fs::read(&path) {
        Ok(bytes) => {
            if let Err(e) = fs::write(out.join("model.magic"), &bytes) {
                fail(&format!("cannot write the model into OUT_DIR: {e}"));
            }
        }
        Err(e) => fail(&format!(
            "MAGIC_MODEL={}: cannot read {}: {e}",
            model.to_string_lossy(),
            path.display()
        )),
    }
}

fn fail(msg: &str) -> ! {
    eprintln!("error: magic-firmware: {msg}");
    exit(1);
}
