//! Semihosting I/O (the measuring build): standard input read in chunks and split into lines, standard output written a
//! line at a time, and the exit call.
//!
//! cortex-m-semihosting writes to the host but has no reader, so the two calls needed here (`OPEN`
//! of `:tt` for reading, `READ`) are made directly with its `syscall!`.

use crate::line::{self, Assembler, Line, Sink};
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

/// Lines from the host's standard input.
pub struct Stdin {
    fd: Option<usize>,
    chunk: [u8; 256],
    pos: usize,
    len: usize,
    eof: bool,
    line: Assembler,
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
            line: Assembler::new(),
        }
    }

    /// The next line, or `None` at the end of the input. A last line without a newline counts.
    pub fn next_line(&mut self) -> Option<Line<'_>> {
        self.line.clear();
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
            self.line.push(b);
        }
        Some(self.line.line())
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

/// A line being written to the host's standard output (one semihosting call per line).
pub type Out = line::Out<HostOut>;

/// The host's standard output as the sink of output lines.
pub struct HostOut(Option<hio::HostStream>);

impl Default for HostOut {
    /// Opens the host's standard output.
    fn default() -> HostOut {
        HostOut(hio::hstdout().ok())
    }
}

impl Sink for HostOut {
    fn send(&mut self, bytes: &[u8]) {
        if let Some(s) = self.0.as_mut() {
            let _ = s.write_all(bytes);
        }
    }
}
