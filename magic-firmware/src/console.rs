//! Lines over the UART (the deployable build): input lines assembled from the receive ring,
//! output lines formatted into a buffer and sent whole.

use crate::line::{strip_cr, Line, LINE_MAX};
use crate::uart;
use core::fmt;

/// Assembles input lines from the bytes the UART received, without blocking: [`Lines::poll`]
/// returns a line once its `\n` has arrived; a partial line waits in the buffer.
pub struct Lines {
    line: [u8; LINE_MAX],
    n: usize,
    too_long: bool,
    /// The last call returned a line: start a new one.
    done: bool,
}

impl Lines {
    /// An empty line buffer.
    pub const fn new() -> Lines {
        Lines {
            line: [0; LINE_MAX],
            n: 0,
            too_long: false,
            done: false,
        }
    }

    /// The next complete line, or `None` while its end has not arrived.
    pub fn poll(&mut self) -> Option<Line<'_>> {
        if self.done {
            self.n = 0;
            self.too_long = false;
            self.done = false;
        }
        while let Some(b) = uart::read_byte() {
            if b == b'\n' {
                self.done = true;
                if self.too_long {
                    return Some(Line::TooLong);
                }
                return Some(Line::Text(strip_cr(self.line.get(..self.n).unwrap_or(&[]))));
            }
            if let Some(slot) = self.line.get_mut(self.n) {
                *slot = b;
                self.n += 1;
            } else {
                self.too_long = true;
            }
        }
        None
    }

    /// Forgets a partial line (after bytes were lost: it is not the line the host sent).
    pub fn discard_partial(&mut self) {
        self.n = 0;
        self.too_long = false;
        self.done = false;
    }
}

/// A line being written to the UART: formatted into a buffer, sent whole by [`Out::end_line`].
pub struct Out {
    buf: [u8; 512],
    n: usize,
}

impl Out {
    /// An empty line.
    pub fn new() -> Out {
        Out {
            buf: [0; 512],
            n: 0,
        }
    }

    /// Ends the current line with `\n` and sends it.
    #[inline(never)]
    pub fn end_line(&mut self) {
        // `n` stays below the buffer's length (`write_str` keeps a byte for the newline).
        if let Some(b) = self.buf.get_mut(self.n) {
            *b = b'\n';
            self.n += 1;
        }
        uart::write_bytes(self.buf.get(..self.n).unwrap_or(&[]));
        self.n = 0;
    }
}

impl fmt::Write for Out {
    /// Appends to the line; text beyond the buffer is cut (answers are far shorter).
    #[inline(never)]
    fn write_str(&mut self, s: &str) -> fmt::Result {
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

/// Core's error messages written piece by piece, numbers by [`crate::text`] (no `core::fmt`).
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
