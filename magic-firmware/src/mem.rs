//! Memory figures read on the board: the stack high-water mark, the statics and the flash used.
//!
//! **Stack.** cortex-m-rt's `paint-stack` feature fills the whole stack region (from the end of
//! the statics, `_stack_end`, to the top of RAM, `_stack_start`) with `0xCCCC_CCCC` before `main`;
//! [`memory`] finds the lowest word that is no longer painted.
//!
//! **Flash.** From the linker's symbols: everything up to the load address of `.data`, plus
//! `.data` itself (its initial values live in flash). In the deployable build the model slots
//! are not part of it (see `slots`).

/// Stack and memory layout read from the linker symbols.
pub struct Memory {
    /// Bytes of stack ever used (highest extent since reset).
    pub stack_used: usize,
    /// Bytes available to the stack (top of RAM down to the end of the statics).
    pub stack_size: usize,
    /// Bytes of flash used (code, constants, the model and `.data` initial values).
    pub flash_used: usize,
    /// Bytes of RAM taken by statics (`.data`, `.bss` and `.uninit`: everything below the stack).
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
    Memory {
        stack_used: top - a,
        stack_size: top - bottom,
        // FLASH starts at 0 on mps2-an386 (memory.x).
        flash_used: sidata + (edata - sdata),
        statics: bottom - sdata,
    }
}
