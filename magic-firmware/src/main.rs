//! # magic-firmware
//!
//! The Cortex-M4F firmware of **magic**, in two builds of the same code (QEMU `mps2-an386` or a
//! board):
//!
//! * **deployable** (`--no-default-features --features uart`): the line protocol on UART0 (the
//!   board's CMSDK APB UART), no semihosting call anywhere. Models are uploaded over the same
//!   line into the second of two flash slots and switched to only after every check; the board
//!   runs the last model switched to after any reset, and a watchdog resets it if it hangs.
//!   See `serve` for the protocol and `README.md` for the layout and budgets.
//! * **measuring** (the default, feature `semihosting`): a model file embedded at build time
//!   (`MAGIC_MODEL`), an observation vector per line read from semihosting stdin, one result line
//!   per input line written to semihosting stdout, then the cost figures as lines starting with
//!   `#` (`# key=value`: executed instructions per inversion under QEMU `-icount shift=0`,
//!   counted with SysTick, split into encoder, Mogi and correction; stack high-water mark; flash).
//!   It exits 0 at the end of the input and non-zero on a bad model, a failed self-check, a fault
//!   or a panic.
//!
//! ```text
//! MAGIC_MODEL=model.magic cargo run -p magic-firmware --target thumbv7em-none-eabihf --profile mcu < obs.csv
//! cargo build -p magic-firmware --target thumbv7em-none-eabihf --profile mcu --no-default-features --features uart
//! ```
//!
//! Both print results exactly as the host's `magic invert` does (`magic_core::line`). On the
//! host the crate is a stub `fn main() {}` so that `cargo test --workspace` builds it.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]
#![deny(unsafe_code)]
#![deny(missing_docs)]

#[cfg(not(target_os = "none"))]
fn main() {}

#[cfg(all(test, target_os = "none"))]
compile_error!("the firmware's tests run on the host: `cargo test -p magic-firmware`");

#[cfg(all(target_os = "none", feature = "semihosting", feature = "uart"))]
compile_error!(
    "the features `semihosting` (measuring build, the default) and `uart` (deployable build) \
     exclude each other: build the deployable firmware with --no-default-features --features uart"
);
#[cfg(all(
    target_os = "none",
    not(feature = "semihosting"),
    not(feature = "uart")
))]
compile_error!(
    "no build chosen: the default features (semihosting, the measuring build) or \
     --no-default-features --features uart (the deployable build)"
);
#[cfg(all(target_os = "none", feature = "uart", feature = "rtm"))]
compile_error!(
    "the deployable build (`uart`) runs Mogi models only: RTM models do not fit its slots"
);

/// The forward models this build links: the Mogi model only (the budgeted firmware), or every
/// problem kind with the feature `rtm`.
#[cfg(all(target_os = "none", not(feature = "rtm")))]
type Linked = magic_core::model_file::MogiOnly;
#[cfg(all(target_os = "none", feature = "rtm"))]
type Linked = magic_core::model_file::AnyProblem;

#[cfg(target_os = "none")]
mod line;
#[cfg(target_os = "none")]
mod mem;
#[cfg(target_os = "none")]
mod rt;
#[cfg(target_os = "none")]
mod selfcheck;
#[cfg(any(target_os = "none", test))]
mod text;

// The measuring build.
#[cfg(all(target_os = "none", feature = "semihosting"))]
mod app;
#[cfg(all(target_os = "none", feature = "semihosting"))]
mod cost;
#[cfg(all(target_os = "none", feature = "semihosting"))]
mod io;
// Either build, with the feature `sd`.
#[cfg(all(target_os = "none", feature = "sd"))]
mod sd;

// The deployable build.
#[cfg(all(target_os = "none", feature = "uart"))]
mod console;
#[cfg(all(target_os = "none", feature = "uart"))]
mod flash;
#[cfg(all(target_os = "none", feature = "uart"))]
mod reset;
#[cfg(all(target_os = "none", feature = "uart"))]
mod serve;
#[cfg(all(target_os = "none", feature = "uart"))]
mod slots;
#[cfg(all(target_os = "none", feature = "uart"))]
mod ticks;
#[cfg(all(target_os = "none", feature = "uart"))]
mod uart;
#[cfg(all(target_os = "none", feature = "uart"))]
mod upload;
#[cfg(all(target_os = "none", feature = "uart"))]
mod wdog;
