//! Entry point, fault and panic handlers: every way out ends the QEMU process with a status, none
//! hangs.

use crate::io::{exit, Out};
use crate::text::write_u32;
use core::fmt::Write;
use cortex_m_rt::{entry, exception, ExceptionFrame};

#[entry]
fn main() -> ! {
    let ok = crate::app::run();
    exit(ok)
}

/// A hard fault (bad memory access, undefined instruction, …): report the faulting address and
/// stop with failure instead of spinning in the default handler. (Decimal: saves the hex
/// formatter's flash.)
#[allow(unsafe_code)]
#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    let mut out = Out::new();
    let _ = out.write_str("error,hardfault: pc=");
    let _ = write_u32(&mut out, ef.pc());
    let _ = out.write_str(" lr=");
    let _ = write_u32(&mut out, ef.lr());
    out.end_line();
    exit(false)
}

/// Any other exception without a handler: same treatment.
#[allow(unsafe_code)]
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    let mut out = Out::new();
    // As u32 (two's complement for the negative system exceptions): saves the i32 formatter.
    let _ = out.write_str("error,unexpected exception ");
    let _ = write_u32(&mut out, irqn as i32 as u32);
    out.end_line();
    exit(false)
}

/// A panic (none is expected: the core returns errors instead). The message and location are not
/// printed: formatting them keeps every panic site's strings and ~1.6 KB of code in flash; the
/// host build of the same code path reports them.
#[cfg(not(feature = "panic-never"))]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    let mut out = Out::new();
    let _ = out.write_str("error,panic");
    out.end_line();
    exit(false)
}

/// With the feature `panic-never`: a panic handler that calls a function defined nowhere. The
/// optimised, fat-LTO build removes every panic the compiler can prove unreachable; if any call
/// of the panic machinery remains, the link fails with "undefined symbol:
/// magic_firmware_panic_is_reachable" and the linker names the functions that reference it.
/// Such a firmware links only when no panic is reachable (it is never meant to run).
#[cfg(feature = "panic-never")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    extern "Rust" {
        fn magic_firmware_panic_is_reachable() -> !;
    }
    // SAFETY: never executed: the symbol is undefined, so a firmware in which this call is
    // reachable does not link.
    #[allow(unsafe_code)]
    unsafe {
        magic_firmware_panic_is_reachable()
    }
}

/// The device-specific part of the vector table: one entry instead of cortex-m-rt's generic 240
/// (960 bytes of flash). The firmware enables no interrupt; cortex-m-rt requires at least one.
#[allow(unsafe_code)]
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
pub static __INTERRUPTS: [unsafe extern "C" fn(); 1] = [default_irq];

#[allow(unsafe_code)]
unsafe extern "C" fn default_irq() {
    let mut out = Out::new();
    let _ = out.write_str("error,unexpected interrupt");
    out.end_line();
    exit(false)
}
