//! Lines over the UART (the deployable build): input lines assembled from the receive ring,
//! output lines sent whole to the UART.

use crate::line::{self, Assembler, Line, Sink};
use crate::uart;

/// A line being written to the UART.
pub type Out = line::Out<Uart>;

/// The UART as the sink of output lines.
#[derive(Default)]
pub struct Uart;

impl Sink for Uart {
    fn send(&mut self, bytes: &[u8]) {
        uart::write_bytes(bytes);
    }
}

/// Assembles input lines from the bytes the UART received, without blocking: [`Lines::poll`]
/// returns a line once its `\n` has arrived; a partial line waits in the buffer.
pub struct Lines {
    line: Assembler,
    /// The last call returned a line: start a new one.
    done: bool,
}

impl Lines {
    /// An empty line buffer.
    pub const fn new() -> Lines {
        Lines {
            line: Assembler::new(),
            done: false,
        }
    }

    /// The next complete line, or `None` while its end has not arrived.
    pub fn poll(&mut self) -> Option<Line<'_>> {
        if self.done {
            self.discard_partial();
        }
        while let Some(b) = uart::read_byte() {
            if b == b'\n' {
                self.done = true;
                return Some(self.line.line());
            }
            self.line.push(b);
        }
        None
    }

    /// Forgets a partial line (after bytes were lost: it is not the line the host sent).
    pub fn discard_partial(&mut self) {
        self.line.clear();
        self.done = false;
    }
}
