//! Entry point, fault and panic handlers, interrupt table. Every way out ends somewhere defined,
//! none hangs: the measuring build ends the QEMU process with a status (semihosting exit), the
//! deployable build reports on the UART and resets the board.

use crate::text::write_u32;
use core::fmt::Write;
use cortex_m_rt::{entry, exception, ExceptionFrame};

#[cfg(feature = "uart")]
use crate::console::Out;
#[cfg(feature = "semihosting")]
use crate::io::Out;

/// How an error line of a fault starts: a result line of the measuring build; an unsolicited
/// line (`!`) of the deployable build.
#[cfg(feature = "semihosting")]
const FAULT: &str = "error,";
#[cfg(feature = "uart")]
const FAULT: &str = "!error,";

/// Stops after a fault: exit with failure (measuring build) or reset (deployable build).
fn stop() -> ! {
    #[cfg(feature = "semihosting")]
    crate::io::exit(false);
    #[cfg(feature = "uart")]
    crate::reset::request(crate::reset::Cause::Fault)
}

#[entry]
fn main() -> ! {
    #[cfg(feature = "semihosting")]
    crate::io::exit(crate::app::run());
    #[cfg(feature = "uart")]
    crate::serve::run()
}

/// A hard fault (bad memory access, undefined instruction, …): report the faulting address and
/// stop instead of spinning in the default handler. (Decimal: saves the hex formatter's flash.)
#[allow(unsafe_code)]
#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    let mut out = Out::new();
    let _ = out.write_str(FAULT);
    let _ = out.write_str("hardfault: pc=");
    let _ = write_u32(&mut out, ef.pc());
    let _ = out.write_str(" lr=");
    let _ = write_u32(&mut out, ef.lr());
    out.end_line();
    stop()
}

/// Any other exception without a handler: same treatment.
#[allow(unsafe_code)]
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    let mut out = Out::new();
    // As u32 (two's complement for the negative system exceptions): saves the i32 formatter.
    let _ = out.write_str(FAULT);
    let _ = out.write_str("unexpected exception ");
    let _ = write_u32(&mut out, irqn as i32 as u32);
    out.end_line();
    stop()
}

/// A panic (none is expected: the core returns errors instead). The message and location are not
/// printed: formatting them keeps every panic site's strings and ~1.6 KB of code in flash; the
/// host build of the same code path reports them.
#[cfg(not(feature = "panic-never"))]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    let mut out = Out::new();
    let _ = out.write_str(FAULT);
    let _ = out.write_str("panic");
    out.end_line();
    stop()
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
/// (960 bytes of flash). The measuring build enables no interrupt (cortex-m-rt requires at least
/// one entry); the deployable build enables entry 0, UART0's receive interrupt on AN386.
#[allow(unsafe_code)]
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
pub static __INTERRUPTS: [unsafe extern "C" fn(); 1] = [
    #[cfg(feature = "semihosting")]
    default_irq,
    #[cfg(feature = "uart")]
    crate::uart::rx_interrupt,
];

#[cfg(feature = "semihosting")]
#[allow(unsafe_code)]
unsafe extern "C" fn default_irq() {
    let mut out = Out::new();
    let _ = out.write_str("error,unexpected interrupt");
    out.end_line();
    stop()
}
