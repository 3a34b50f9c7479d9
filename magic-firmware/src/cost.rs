//! Cost figures measured on the (emulated) board: executed instructions, stack and flash.
//!
//! **Instructions.** QEMU is not cycle-accurate, but with `-icount shift=0` its virtual clock
//! advances exactly 1 ns per executed instruction, and SysTick on `mps2-an386` counts the 25 MHz
//! system clock from that virtual clock: one tick per 40 instructions. [`Clock`] reads SysTick
//! around a piece of code; a single reading is exact to ±40 instructions, a mean over many
//! inversions much better. [`Clock::calibrate`] times a loop of known length, so that a run
//! without `-icount shift=0` (where SysTick follows host time) is detected instead of reported.
//!
//! **Stack.** cortex-m-rt's `paint-stack` feature fills the whole stack region (from the end of
//! the statics, `_stack_end`, to the top of RAM, `_stack_start`) with `0xCCCC_CCCC` before `main`;
//! [`stack_high_water`] finds the lowest word that is no longer painted.
//!
//! **Flash.** From the linker's symbols: everything up to the load address of `.data`, plus
//! `.data` itself (its initial values live in flash).

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

/// Stack and memory layout read from the linker symbols.
pub struct Memory {
    /// Bytes of stack ever used (highest extent since reset).
    pub stack_used: usize,
    /// Bytes available to the stack (top of RAM down to the end of the statics).
    pub stack_size: usize,
    /// Bytes of flash used (code, constants, the model and `.data` initial values).
    pub flash_used: usize,
    /// Bytes of RAM taken by statics (`.data` + `.bss`).
    pub statics: usize,
}

/// The paint value of cortex-m-rt's `paint-stack` feature.
const PAINT: u32 = 0xCCCC_CCCC;

extern "C" {
    static _stack_start: u32;
    static _stack_end: u32;
    static __sdata: u32;
    static __edata: u32;
    static __sidata: u32;
    static __ebss: u32;
}

/// Measures the stack high-water mark and reads the flash and RAM layout.
#[allow(unsafe_code)]
pub fn memory() -> Memory {
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let bottom = core::ptr::addr_of!(_stack_end) as usize;
    let mut a = bottom;
    while a < top {
        // SAFETY: [bottom, top) is the stack region of RAM defined by the linker script, word
        // aligned (cortex-m-rt asserts it); reading it volatile has no side effects.
        let v = unsafe { core::ptr::read_volatile(a as *const u32) };
        if v != PAINT {
            break;
        }
        a += 4;
    }
    let sdata = core::ptr::addr_of!(__sdata) as usize;
    let edata = core::ptr::addr_of!(__edata) as usize;
    let sidata = core::ptr::addr_of!(__sidata) as usize;
    let ebss = core::ptr::addr_of!(__ebss) as usize;
    Memory {
        stack_used: top - a,
        stack_size: top - bottom,
        // FLASH starts at 0 on mps2-an386 (memory.x).
        flash_used: sidata + (edata - sdata),
        statics: ebss - sdata,
    }
}
