//! UART0 of the board (the deployable build): the CMSDK APB UART of `mps2-an386`, transmit polled,
//! receive driven by its interrupt into a ring buffer.
//!
//! The device (Arm, *Cortex-M System Design Kit Technical Reference Manual*, DDI 0479, "APB
//! UART"; at `0x4000_4000` on the AN385/AN386 images, receive interrupt IRQ 0) has one register
//! per direction:
//!
//! | offset | register | used here |
//! |---|---|---|
//! | `0x00` | DATA | the received byte (read) / the byte to send (write) |
//! | `0x04` | STATE | bit 0 transmit full, bit 1 receive full, bit 3 receive overrun (write 1 to clear) |
//! | `0x08` | CTRL | bit 0 transmit enable, bit 1 receive enable, bit 3 receive interrupt enable |
//! | `0x0C` | INTSTATUS / INTCLEAR | bit 1 receive interrupt (write 1 to clear) |
//! | `0x10` | BAUDDIV | clock / baud rate, at least 16 |
//!
//! The receive register holds a single byte: whatever arrives while the program is busy (an
//! inversion, a flash write) must be taken by the interrupt, which moves each byte into
//! [`RX_BUF`] bytes of ring buffer; the main loop takes them out with [`read_byte`]. The host
//! keeps at most [`RX_BUF`] bytes of unanswered lines in flight (the board announces the size),
//! so the ring never overflows; if it does (or the device reports an overrun), the bytes are
//! counted in [`lost`] and the board says so.
//!
//! QEMU connects UART0 to its first `-serial` and takes a new byte from it only once the guest
//! has read the last one, so under QEMU nothing is ever lost, whatever the buffer.

use core::cell::UnsafeCell;
use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicU32, Ordering};

/// UART0 of mps2-an386.
const BASE: usize = 0x4000_4000;
const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const INTCLEAR: usize = 0x0C;
const BAUDDIV: usize = 0x10;

const TX_FULL: u32 = 1 << 0;
const RX_FULL: u32 = 1 << 1;
const RX_OVERRUN: u32 = 1 << 3;
const TX_ENABLE: u32 = 1 << 0;
const RX_ENABLE: u32 = 1 << 1;
const RX_INT_ENABLE: u32 = 1 << 3;
const RX_INT: u32 = 1 << 1;

/// The peripheral clock of the board (25 MHz on mps2-an386).
pub const CLOCK_HZ: u32 = 25_000_000;
/// The line speed: 115 200 baud, 8 data bits, no parity, one stop bit (the device's only frame).
pub const BAUD: u32 = 115_200;

/// Bytes of receive buffer: the most the host may send ahead of the board's answers.
pub const RX_BUF: usize = 2048;
const _: () = assert!(RX_BUF.is_power_of_two());

/// The receive interrupt's number on AN386 (entry 0 of the interrupt vector table).
#[derive(Clone, Copy)]
struct Uart0Rx;

// SAFETY: 0 is UART0's receive interrupt on the AN385/AN386 images (and on QEMU's model of them).
#[allow(unsafe_code)]
unsafe impl cortex_m::interrupt::InterruptNumber for Uart0Rx {
    fn number(self) -> u16 {
        0
    }
}

#[allow(unsafe_code)]
fn read(offset: usize) -> u32 {
    // SAFETY: an aligned word register of UART0 (memory-mapped I/O, always present).
    unsafe { read_volatile((BASE + offset) as *const u32) }
}

#[allow(unsafe_code)]
fn write(offset: usize, v: u32) {
    // SAFETY: as in `read`.
    unsafe { write_volatile((BASE + offset) as *mut u32, v) }
}

/// The receive ring: written by the interrupt (at `head`), read by the main loop (at `tail`).
/// Indices run freely and wrap; `head − tail` bytes are waiting.
struct Ring {
    buf: UnsafeCell<[u8; RX_BUF]>,
    head: AtomicU32,
    tail: AtomicU32,
    lost: AtomicU32,
}

// SAFETY: one producer (the interrupt handler, which never nests with itself) writes only the
// free part of `buf` and publishes it with `head` (Release); one consumer (the main loop) reads
// only the published part (Acquire) and frees it with `tail`. Single core.
#[allow(unsafe_code)]
unsafe impl Sync for Ring {}

static RX: Ring = Ring {
    buf: UnsafeCell::new([0; RX_BUF]),
    head: AtomicU32::new(0),
    tail: AtomicU32::new(0),
    lost: AtomicU32::new(0),
};

const MASK: u32 = RX_BUF as u32 - 1;

/// Sets the line speed, enables transmit, receive and the receive interrupt.
pub fn init() {
    write(BAUDDIV, CLOCK_HZ / BAUD);
    write(CTRL, TX_ENABLE | RX_ENABLE | RX_INT_ENABLE);
    // SAFETY: the handler (`rx_interrupt`) touches only the ring's free part and atomics.
    #[allow(unsafe_code)]
    unsafe {
        cortex_m::peripheral::NVIC::unmask(Uart0Rx)
    };
}

/// The receive interrupt: moves every waiting byte into the ring.
#[allow(unsafe_code)]
pub unsafe extern "C" fn rx_interrupt() {
    // Clear first: a byte that arrives after the last read below raises the interrupt again
    // (cleared after the loop, it would be forgotten, and QEMU would send nothing more).
    write(INTCLEAR, RX_INT);
    while read(STATE) & RX_FULL != 0 {
        let b = read(DATA) as u8;
        let head = RX.head.load(Ordering::Relaxed);
        let tail = RX.tail.load(Ordering::Acquire);
        if head.wrapping_sub(tail) >= RX_BUF as u32 {
            RX.lost.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        // SAFETY: slot `head` is free (checked above) and only this handler writes free slots.
        unsafe {
            if let Some(slot) = (*RX.buf.get()).get_mut((head & MASK) as usize) {
                *slot = b;
            }
        }
        RX.head.store(head.wrapping_add(1), Ordering::Release);
    }
    if read(STATE) & RX_OVERRUN != 0 {
        write(STATE, RX_OVERRUN);
        RX.lost.fetch_add(1, Ordering::Relaxed);
    }
}

/// The next received byte, if any.
#[allow(unsafe_code)]
pub fn read_byte() -> Option<u8> {
    let tail = RX.tail.load(Ordering::Relaxed);
    if RX.head.load(Ordering::Acquire) == tail {
        return None;
    }
    // SAFETY: slot `tail` is published (head != tail) and the interrupt does not write it
    // until `tail` moves past it below.
    let b = unsafe { (*RX.buf.get()).get((tail & MASK) as usize).copied() };
    RX.tail.store(tail.wrapping_add(1), Ordering::Release);
    b
}

/// Sleeps until an interrupt (a received byte, the clock tick) unless a byte is already waiting.
pub fn wait_for_input() {
    cortex_m::interrupt::free(|_| {
        // With interrupts masked, a byte arriving between the test and `wfi` still ends the
        // wait (WFI wakes on a pending interrupt); it is taken when they are unmasked.
        if RX.head.load(Ordering::Acquire) == RX.tail.load(Ordering::Relaxed) {
            cortex_m::asm::wfi();
        }
    });
}

/// Bytes lost since start-up (ring full or device overrun), as a running count.
pub fn lost() -> u32 {
    RX.lost.load(Ordering::Relaxed)
}

/// Sends bytes, waiting for the transmit register as needed.
pub fn write_bytes(bytes: &[u8]) {
    for &b in bytes {
        while read(STATE) & TX_FULL != 0 {}
        write(DATA, u32::from(b));
    }
}
