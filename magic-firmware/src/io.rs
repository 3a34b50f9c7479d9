//! Semihosting I/O (the measuring build): standard input read in chunks and split into lines, standard output written a
//! line at a time, and the exit call.
//!
//! cortex-m-semihosting writes to the host but has no reader, so the two calls needed here (`OPEN`
//! of `:tt` for reading, `READ`) are made directly with its `syscall!`.

use crate::line::{strip_cr, Line, LINE_MAX};
use core::fmt;
use cortex_m_semihosting::{debug, hio};

/// Ends the program: semihosting exit with success or failure (QEMU exits 0 or 1).
pub fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    // Not reached under QEMU; on a board without a debugger attached, stop here.
    loop {
        cortex_m::asm::bkpt();
    }
}

/// Lines from the host's standard input.
pub struct Stdin {
    fd: Option<usize>,
    chunk: [u8; 256],
    pos: usize,
    len: usize,
    eof: bool,
    line: [u8; LINE_MAX],
    n: usize,
    too_long: bool,
}

#[allow(unsafe_code)]
fn sys_open_stdin() -> Option<usize> {
    const NAME: &[u8] = b":tt\0";
    // SAFETY: semihosting OPEN reads `len` bytes of a NUL-terminated name that outlives the call
    // (a static); mode 0 is "r", which QEMU maps `:tt` to its standard input.
    let fd = unsafe { cortex_m_semihosting::syscall!(OPEN, NAME.as_ptr(), 0usize, NAME.len() - 1) }
        as isize;
    (fd >= 0).then_some(fd as usize)
}

#[allow(unsafe_code)]
fn sys_read(fd: usize, buf: &mut [u8]) -> Option<usize> {
    // SAFETY: semihosting READ writes at most `buf.len()` bytes into `buf`, which is exclusively
    // borrowed for the duration of the call.
    let left = unsafe { cortex_m_semihosting::syscall!(READ, fd, buf.as_mut_ptr(), buf.len()) };
    // READ returns the number of bytes *not* read; anything larger than the request is an error.
    (left <= buf.len()).then(|| buf.len() - left)
}

impl Stdin {
    /// Opens the host's standard input.
    pub fn open() -> Stdin {
        Stdin {
            fd: sys_open_stdin(),
            chunk: [0; 256],
            pos: 0,
            len: 0,
            eof: false,
            line: [0; LINE_MAX],
            n: 0,
            too_long: false,
        }
    }

    /// The next line, or `None` at the end of the input. A last line without a newline counts.
    pub fn next_line(&mut self) -> Option<Line<'_>> {
        self.n = 0;
        self.too_long = false;
        let mut any = false;
        loop {
            if self.pos == self.len {
                if self.eof || !self.refill() {
                    if !any {
                        return None;
                    }
                    break;
                }
                continue;
            }
            let Some(&b) = self.chunk.get(self.pos) else {
                // (`pos < len ≤ chunk.len()`: not reached.)
                self.pos = self.len;
                continue;
            };
            self.pos += 1;
            any = true;
            if b == b'\n' {
                break;
            }
            if let Some(slot) = self.line.get_mut(self.n) {
                *slot = b;
                self.n += 1;
            } else {
                self.too_long = true;
            }
        }
        if self.too_long {
            return Some(Line::TooLong);
        }
        Some(Line::Text(strip_cr(self.line.get(..self.n).unwrap_or(&[]))))
    }

    fn refill(&mut self) -> bool {
        let Some(fd) = self.fd else {
            self.eof = true;
            return false;
        };
        match sys_read(fd, &mut self.chunk) {
            Some(n) if n > 0 => {
                self.pos = 0;
                self.len = n;
                true
            }
            _ => {
                self.eof = true;
                false
            }
        }
    }
}

/// A line being written to the host's standard output: formatted into a buffer, sent whole by
/// [`Out::end_line`] (one semihosting call per line).
pub struct Out {
    stream: Option<hio::HostStream>,
    buf: [u8; 512],
    n: usize,
}

impl Out {
    /// Opens the host's standard output.
    pub fn new() -> Out {
        Out {
            stream: hio::hstdout().ok(),
            buf: [0; 512],
            n: 0,
        }
    }

    /// Ends the current line with `\n` and sends it.
    #[inline(never)]
    pub fn end_line(&mut self) {
        // `n` stays below the buffer's length (`write_str` keeps a byte for the newline); the
        // checked accesses cost nothing and keep the code free of panics.
        if let Some(b) = self.buf.get_mut(self.n) {
            *b = b'\n';
            self.n += 1;
        }
        if let (Some(s), Some(line)) = (self.stream.as_mut(), self.buf.get(..self.n)) {
            let _ = s.write_all(line);
        }
        self.n = 0;
    }
}

impl fmt::Write for Out {
    /// Appends to the line; text beyond the buffer is cut (result lines are far shorter).
    #[inline(never)]
    fn write_str(&mut self, s: &str) -> fmt::Result {
        // Keep one byte for the newline.
        let room = (self.buf.len() - 1).saturating_sub(self.n);
        let k = s.len().min(room);
        if let (Some(dst), Some(src)) =
            (self.buf.get_mut(self.n..self.n + k), s.as_bytes().get(..k))
        {
            dst.copy_from_slice(src);
            self.n += k;
        }
        Ok(())
    }
}

/// Core's error messages written piece by piece, numbers by [`crate::text`]: the same words as
/// its `Display`, without `core::fmt`'s formatting code.
impl magic_core::MessageSink for Out {
    fn text(&mut self, s: &str) {
        let _ = fmt::Write::write_str(self, s);
    }
    fn number(&mut self, n: u32) {
        let _ = crate::text::write_u32(self, n);
    }
    fn hex(&mut self, n: u32) {
        let _ = crate::text::write_hex32(self, n);
    }
}
