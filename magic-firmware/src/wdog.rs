//! The watchdog (the deployable build): the CMSDK APB watchdog of `mps2-an386` (Arm DDI 0479,
//! "APB watchdog"; at `0x4000_8000`, clocked at 25 MHz, its interrupt wired to the NMI).
//!
//! It counts down from `LOAD`; at zero it raises its interrupt and reloads, and at zero again,
//! the interrupt still pending, it resets the system. The main loop feeds it (clears the
//! interrupt, which reloads the count) on every pass, whether a line arrived or the tick woke
//! it, so a program stuck anywhere for [`TIMEOUT_MS`] gets an NMI, which records the cause, and
//! after twice that a reset. QEMU models it (first expiry: NMI; second: a system reset).
//!
//! | offset | register |
//! |---|---|
//! | `0x000` | LOAD |
//! | `0x008` | CONTROL: bit 0 interrupt (and counter) enable, bit 1 reset enable |
//! | `0x00C` | INTCLR: any write clears the interrupt and reloads the counter |
//! | `0xC00` | LOCK: `0x1ACC_E551` unlocks writes, anything else locks them |

use crate::reset::{self, Cause};
use core::ptr::write_volatile;
use cortex_m_rt::exception;

const BASE: usize = 0x4000_8000;
const LOAD: usize = 0x000;
const CONTROL: usize = 0x008;
const INTCLR: usize = 0x00C;
const LOCK: usize = 0xC00;
const UNLOCK: u32 = 0x1ACC_E551;
const INT_ENABLE: u32 = 1 << 0;
const RESET_ENABLE: u32 = 1 << 1;

/// Milliseconds without feeding before the NMI; the reset follows after as long again.
pub const TIMEOUT_MS: u32 = 1000;
/// The watchdog's clock on mps2-an386.
const CLOCK_HZ: u32 = 25_000_000;

#[allow(unsafe_code)]
fn write(offset: usize, v: u32) {
    // SAFETY: an aligned word register of the watchdog (memory-mapped I/O, always present).
    unsafe { write_volatile((BASE + offset) as *mut u32, v) }
}

/// Starts the watchdog with [`TIMEOUT_MS`], interrupt and reset enabled, and locks it.
pub fn start() {
    write(LOCK, UNLOCK);
    write(LOAD, CLOCK_HZ / 1000 * TIMEOUT_MS);
    write(CONTROL, INT_ENABLE | RESET_ENABLE);
    write(LOCK, 0);
}

/// Feeds the watchdog: the count starts again from [`TIMEOUT_MS`].
pub fn feed() {
    write(LOCK, UNLOCK);
    write(INTCLR, 1);
    write(LOCK, 0);
    // A recovered warning (the NMI came, then the program went on) is no cause of a reset.
    if reset::is(Cause::Watchdog) {
        reset::note(Cause::Other);
    }
}

/// The watchdog's first expiry: the program has not fed it for [`TIMEOUT_MS`]. Records the
/// cause; the reset follows unless the program recovers and feeds it in time.
#[allow(unsafe_code)]
#[exception]
unsafe fn NonMaskableInt() {
    reset::note(Cause::Watchdog);
}
