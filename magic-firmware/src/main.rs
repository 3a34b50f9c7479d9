//! # magic-firmware
//!
//! The Cortex-M4F example of **magic**: a model file embedded at build time (`MAGIC_MODEL`), an
//! observation vector per line read from semihosting stdin, one result line per input line written
//! to semihosting stdout, exactly as the host's `magic invert` prints them
//! ([`magic_core::line`]). It runs on QEMU's `mps2-an386` board:
//!
//! ```text
//! MAGIC_MODEL=model.magic cargo run -p magic-firmware --target thumbv7em-none-eabihf --profile mcu < obs.csv
//! ```
//!
//! After the last result line it prints its cost figures as lines starting with `#`
//! (`# key=value`): executed instructions per inversion (QEMU `-icount shift=0`, counted with
//! SysTick), split into encoder, Mogi and correction, the stack high-water mark and the flash
//! used. It exits 0 at the end of the input and non-zero (semihosting failure) on a bad model, a
//! failed self-check, a fault or a panic.
//!
//! On the host the crate is a stub `fn main() {}` so that `cargo test --workspace` builds it.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]
#![deny(unsafe_code)]
#![deny(missing_docs)]

#[cfg(not(target_os = "none"))]
fn main() {}

#[cfg(all(test, target_os = "none"))]
compile_error!("the firmware's tests run on the host: `cargo test -p magic-firmware`");

#[cfg(target_os = "none")]
mod app;
#[cfg(target_os = "none")]
mod cost;
#[cfg(target_os = "none")]
mod io;
#[cfg(target_os = "none")]
mod rt;
#[cfg(any(target_os = "none", test))]
mod text;
