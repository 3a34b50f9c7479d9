//! Milliseconds since start-up (the deployable build), counted by SysTick interrupts every
//! [`TICK_MS`] ms: the upload timeout is measured with them, and the tick also wakes the idle
//! loop so that it feeds the watchdog.
//!
//! SysTick counts the core clock, 25 MHz on mps2-an386. Under QEMU without `-icount` the clock
//! follows host time; with `-icount shift=0` it follows the executed instructions (1 ns each).

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::exception;

/// The core clock of mps2-an386.
pub const CORE_HZ: u32 = 25_000_000;
/// Milliseconds per tick.
pub const TICK_MS: u32 = 10;

static TICKS: AtomicU32 = AtomicU32::new(0);

/// Starts the tick interrupt.
pub fn start(mut syst: SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(CORE_HZ / 1000 * TICK_MS - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Milliseconds since [`start`] (wraps after 49 days; compare with `wrapping_sub`).
pub fn now_ms() -> u32 {
    TICKS.load(Ordering::Relaxed).wrapping_mul(TICK_MS)
}

#[exception]
fn SysTick() {
    TICKS.fetch_add(1, Ordering::Relaxed);
}
