//! Writing the board's flash (the deployable build): the [`Flash`] trait the model slots are
//! written through, and its implementation for QEMU's `mps2-an386`, whose "flash" is writable
//! memory.
//!
//! Flash is read like memory (internal flash of Cortex-M parts is memory-mapped); only erasing
//! and programming go through the trait, so that a board's flash controller (unlock, erase a
//! page, program words, wait for the busy bit) replaces [`RamFlash`] without touching the slot
//! logic. The contract is NOR flash's: a page must be erased (every byte `0xFF`) before it is
//! programmed, programming can only clear bits, and every write is checked by reading it back.

/// Why an erase or a write failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// The address or length is not aligned to the page or program unit.
    Misaligned,
    /// Outside the writable region (the model slots and their headers).
    OutOfRange,
    /// What was read back is not what was written (e.g. the page was not erased).
    Verify,
}

impl FlashError {
    /// The words of an error line.
    pub fn message(self) -> &'static str {
        match self {
            FlashError::Misaligned => "flash: misaligned write",
            FlashError::OutOfRange => "flash: write outside the model slots",
            FlashError::Verify => "flash: read back differs from what was written",
        }
    }
}

/// Erasing and programming flash.
pub trait Flash {
    /// The erase unit, bytes (a power of two).
    const PAGE: usize;
    /// The program unit, bytes (a power of two that divides 32).
    const WORD: usize;
    /// Erases the page at `addr` (a multiple of [`Flash::PAGE`]): every byte reads `0xFF`.
    fn erase_page(&mut self, addr: usize) -> Result<(), FlashError>;
    /// Programs `data` at `addr` (both multiples of [`Flash::WORD`]) into erased flash and
    /// checks it.
    fn program(&mut self, addr: usize, data: &[u8]) -> Result<(), FlashError>;
}

/// `len` bytes of flash at `addr`, read as memory.
#[allow(unsafe_code)]
pub fn read(addr: usize, len: usize) -> &'static [u8] {
    // SAFETY: callers pass ranges inside the model slots or their headers (flash that is always
    // mapped); the bytes change only through `Flash`, and the slot logic never writes a slot or
    // header page while a slice of it is in use (see `slots`).
    unsafe { core::slice::from_raw_parts(addr as *const u8, len) }
}

/// QEMU's flash: `mps2-an386` maps 4 MiB of RAM at 0 where the board has flash. Erase and
/// program emulate NOR flash (erase sets bytes to `0xFF`, programming ANDs bits in), so that a
/// write to a page that was not erased fails its check here as it would on a board. Writes are
/// confined to `[start, end)`, the region of the model slots and headers.
pub struct RamFlash {
    start: usize,
    end: usize,
}

impl RamFlash {
    /// Flash writable between `start` and `end`.
    pub fn new(start: usize, end: usize) -> RamFlash {
        RamFlash { start, end }
    }

    fn check(&self, addr: usize, len: usize, align: usize) -> Result<(), FlashError> {
        if addr % align != 0 || len % align != 0 {
            return Err(FlashError::Misaligned);
        }
        match addr.checked_add(len) {
            Some(e) if addr >= self.start && e <= self.end => Ok(()),
            _ => Err(FlashError::OutOfRange),
        }
    }
}

impl Flash for RamFlash {
    const PAGE: usize = 4096;
    const WORD: usize = 4;

    #[allow(unsafe_code)]
    fn erase_page(&mut self, addr: usize) -> Result<(), FlashError> {
        self.check(addr, Self::PAGE, Self::PAGE)?;
        for a in (addr..addr + Self::PAGE).step_by(4) {
            // SAFETY: inside the writable region (checked), word aligned; no slice of this page
            // is alive (the slot logic's rule).
            unsafe { core::ptr::write_volatile(a as *mut u32, u32::MAX) };
        }
        if read(addr, Self::PAGE).iter().all(|&b| b == 0xFF) {
            Ok(())
        } else {
            Err(FlashError::Verify)
        }
    }

    #[allow(unsafe_code)]
    fn program(&mut self, addr: usize, data: &[u8]) -> Result<(), FlashError> {
        self.check(addr, data.len(), Self::WORD)?;
        for (a, &b) in (addr..).zip(data) {
            // SAFETY: as in `erase_page`.
            unsafe {
                let p = a as *mut u8;
                core::ptr::write_volatile(p, core::ptr::read_volatile(p) & b);
            }
        }
        if read(addr, data.len()) == data {
            Ok(())
        } else {
            Err(FlashError::Verify)
        }
    }
}
