//! Cost figures measured on the (emulated) board (the measuring build): executed instructions.
//!
//! **Instructions.** QEMU is not cycle-accurate, but with `-icount shift=0` its virtual clock
//! advances exactly 1 ns per executed instruction, and SysTick on `mps2-an386` counts the 25 MHz
//! system clock from that virtual clock: one tick per 40 instructions. [`Clock`] reads SysTick
//! around a piece of code; a single reading is exact to ±40 instructions, a mean over many
//! inversions much better. [`Clock::calibrate`] times a loop of known length, so that a run
//! without `-icount shift=0` (where SysTick follows host time) is detected instead of reported.
//!
//! Stack, statics and flash are read by [`crate::mem`].

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;

/// Instructions per SysTick tick under `-icount shift=0` (25 MHz clock, 1 ns per instruction).
pub const INSTRUCTIONS_PER_TICK: u32 = 40; // also in the report's header line
const RELOAD: u32 = 0x00FF_FFFF;

/// SysTick as a free-running down-counter of the core clock.
pub struct Clock {
    _syst: SYST,
}

impl Clock {
    /// Starts SysTick on the core clock, counting down from 2²⁴ − 1, no interrupt.
    pub fn start(mut syst: SYST) -> Clock {
        syst.disable_interrupt();
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(RELOAD);
        syst.clear_current();
        syst.enable_counter();
        Clock { _syst: syst }
    }

    /// The current count (ticks, counting down).
    #[inline(always)]
    pub fn now(&self) -> u32 {
        SYST::get_current()
    }

    /// Instructions elapsed since `start` (a reading of [`Clock::now`]); valid below 2²⁴ ticks.
    #[inline(always)]
    pub fn since(&self, start: u32) -> u32 {
        (start.wrapping_sub(self.now()) & RELOAD) * INSTRUCTIONS_PER_TICK
    }

    /// Times a loop of exactly `2 · n` instructions; returns instructions measured per
    /// instruction executed, ×1000 (1000 when the clock follows the instruction count).
    pub fn calibrate(&self, n: u32) -> u32 {
        let t = self.now();
        spin(n);
        let got = self.since(t) as u64;
        div_round(got * 1000, 2 * n.max(1) as u64) as u32
    }
}

/// A loop of exactly `2 · n` instructions (`subs`, `bne`), for calibration.
#[allow(unsafe_code)]
#[inline(never)]
fn spin(n: u32) {
    if n == 0 {
        return;
    }
    // SAFETY: register-only arithmetic and a local branch; no memory is touched.
    unsafe {
        core::arch::asm!(
            "2:",
            "subs {0}, {0}, #1",
            "bne 2b",
            inout(reg) n => _,
            options(nomem, nostack),
        );
    }
}

/// Running statistics of a cost in instructions.
#[derive(Clone, Copy, Default)]
pub struct Stat {
    /// Number of samples.
    pub n: u32,
    /// Sum of the samples.
    pub sum: u64,
    /// Smallest sample.
    pub min: u32,
    /// Largest sample.
    pub max: u32,
}

impl Stat {
    /// Adds a sample.
    pub fn add(&mut self, v: u32) {
        if self.n == 0 || v < self.min {
            self.min = v;
        }
        if v > self.max {
            self.max = v;
        }
        self.n += 1;
        self.sum += v as u64;
    }

    /// Mean, rounded.
    pub fn mean(&self) -> u32 {
        div_round(self.sum, self.n as u64) as u32
    }
}

/// `n / d` rounded half up (0 when `d` is 0), by binary long division: neither soft-float f64 nor
/// the 64-bit division routine (about 1 KB of flash each) is linked for the cost figures.
pub fn div_round(n: u64, d: u64) -> u64 {
    if d == 0 {
        return 0;
    }
    let n = n.saturating_add(d / 2);
    let (mut q, mut r) = (0u64, 0u64);
    for i in (0..64).rev() {
        r = (r << 1) | ((n >> i) & 1);
        if r >= d {
            r -= d;
            q |= 1 << i;
        }
    }
    q
}
