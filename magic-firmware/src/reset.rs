//! Resets of the board (the deployable build): the request (SYSRESETREQ) and why the last one
//! happened, kept in two words of RAM that neither start-up nor QEMU clears (`KEEP` in
//! `memory-uart.x`, outside every section), so that the board can say it in its start-up line
//! (`reset=…`).
//!
//! RAM keeps its contents across a system reset (on QEMU's mps2-an386 as on the board), not
//! across a power cycle: a cell without its check word reads as a power-on.

/// Why the board started.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Cause {
    /// Power was applied (or the RAM cell was never written).
    PowerOn,
    /// The host asked for it (`!reset`).
    Command,
    /// The watchdog was not fed in time.
    Watchdog,
    /// A fault or a panic.
    Fault,
    /// A reset nobody recorded (reset pin, debugger).
    Other,
}

impl Cause {
    /// The word of the start-up line.
    pub fn name(self) -> &'static str {
        match self {
            Cause::PowerOn => "power-on",
            Cause::Command => "command",
            Cause::Watchdog => "watchdog",
            Cause::Fault => "fault",
            Cause::Other => "other",
        }
    }

    fn code(self) -> u32 {
        match self {
            Cause::PowerOn => 1,
            Cause::Command => 2,
            Cause::Watchdog => 3,
            Cause::Fault => 4,
            Cause::Other => 5,
        }
    }
}

/// Check word of the cell.
const MAGIC: u32 = 0x5E5E_7C0D;

extern "C" {
    /// `[MAGIC, cause code]`: the start of `KEEP` (its address is the symbol's).
    static __reset_cause: u32;
}

fn cell() -> *mut u32 {
    core::ptr::addr_of!(__reset_cause) as *mut u32
}

/// Records why the next reset happens.
#[allow(unsafe_code)]
pub fn note(cause: Cause) {
    // SAFETY: word writes to RAM that only this module touches (KEEP, reserved by the linker
    // script); the NMI handler may interrupt a note of the main loop, and then its (later) cause
    // wins, which is the one that resets.
    unsafe {
        let p = cell();
        core::ptr::write_volatile(p, MAGIC);
        core::ptr::write_volatile(p.add(1), cause.code());
    }
}

/// Why the board started; from now on a reset nobody notes reads as [`Cause::Other`].
#[allow(unsafe_code)]
pub fn take() -> Cause {
    // SAFETY: two aligned words of RAM reserved for this (KEEP); after a power-on they hold
    // arbitrary bits, which the check word tells apart.
    let (magic, code) = unsafe {
        let p = cell();
        (
            core::ptr::read_volatile(p),
            core::ptr::read_volatile(p.add(1)),
        )
    };
    let cause = match (magic == MAGIC, code) {
        (true, 2) => Cause::Command,
        (true, 3) => Cause::Watchdog,
        (true, 4) => Cause::Fault,
        (true, 5) => Cause::Other,
        _ => Cause::PowerOn,
    };
    note(Cause::Other);
    cause
}

/// Whether the recorded cause is `cause`.
#[allow(unsafe_code)]
pub fn is(cause: Cause) -> bool {
    // SAFETY: as in `take` (the cell has been written by then).
    let code = unsafe { core::ptr::read_volatile(cell().add(1)) };
    code == cause.code()
}

/// Resets the board (SYSRESETREQ), recording why.
pub fn request(cause: Cause) -> ! {
    note(cause);
    cortex_m::peripheral::SCB::sys_reset()
}
