//! The firmware from the host: build the Cortex-M4F image with a model embedded, run it under
//! QEMU with observation lines, and compare its results and cost figures with the host's; the
//! deployable build on its UART, and the station's end of its line protocol.

pub mod qemu;
pub mod qemu_uart;
pub mod run;
pub mod station;

pub use qemu::{build_firmware, run_firmware, FirmwareRun};
pub use run::{agreement, run_rows, run_rows_with, run_test_days, sd_agreement};
