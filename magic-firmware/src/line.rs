//! Lines in and out, whatever carries them (semihosting or the UART): an input line assembled
//! byte by byte up to the longest line accepted, and an output line formatted into a buffer and
//! handed whole to the build's [`Sink`].

use core::fmt;

/// Longest input line accepted (bytes, without the newline): 96 channels of 10 characters fit.
pub const LINE_MAX: usize = 1024;

/// The answer to an input line longer than [`LINE_MAX`] (a constant: no formatting code).
pub const LINE_TOO_LONG: &str = "error,line longer than 1024 bytes";
const _: () = assert!(LINE_MAX == 1024, "update LINE_TOO_LONG");

/// Longest output line (bytes, with its newline): result lines are far shorter.
const OUT_MAX: usize = 512;

/// One input line as read.
pub enum Line<'a> {
    /// The bytes of the line without its end (`\n`, `\r\n`).
    Text(&'a [u8]),
    /// The line was longer than [`LINE_MAX`] (the rest of it was skipped).
    TooLong,
}

/// The bytes of a line without a trailing `\r` (a `\r\n` line end).
fn strip_cr(bytes: &[u8]) -> &[u8] {
    match bytes {
        [rest @ .., b'\r'] => rest,
        _ => bytes,
    }
}

/// An input line being assembled: bytes beyond [`LINE_MAX`] are dropped and the line is marked
/// too long.
pub struct Assembler {
    line: [u8; LINE_MAX],
    /// Bytes kept, or `LINE_MAX + 1` once the line ran past [`LINE_MAX`].
    n: usize,
}

impl Assembler {
    /// An empty line.
    pub const fn new() -> Assembler {
        Assembler {
            line: [0; LINE_MAX],
            n: 0,
        }
    }

    /// Starts a new line.
    pub fn clear(&mut self) {
        self.n = 0;
    }

    /// Appends a byte (not the newline).
    pub fn push(&mut self, b: u8) {
        if let Some(slot) = self.line.get_mut(self.n) {
            *slot = b;
            self.n += 1;
        } else {
            self.n = LINE_MAX + 1;
        }
    }

    /// The line assembled so far.
    pub fn line(&self) -> Line<'_> {
        match self.line.get(..self.n) {
            Some(bytes) => Line::Text(strip_cr(bytes)),
            None => Line::TooLong,
        }
    }
}

/// Where a finished output line goes (semihosting stdout, the UART).
pub trait Sink: Default {
    /// Sends the bytes of one line, its newline included.
    fn send(&mut self, bytes: &[u8]);
}

/// A line being written: formatted into a buffer, sent whole by [`Out::end_line`].
pub struct Out<S> {
    sink: S,
    buf: [u8; OUT_MAX],
    n: usize,
}

impl<S: Sink> Out<S> {
    /// An empty line on the build's sink.
    pub fn new() -> Out<S> {
        Out {
            sink: S::default(),
            buf: [0; OUT_MAX],
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
        self.sink.send(self.buf.get(..self.n).unwrap_or(&[]));
        self.n = 0;
    }
}

impl<S: Sink> fmt::Write for Out<S> {
    /// Appends to the line; text beyond the buffer is cut (answers are far shorter).
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
impl<S: Sink> magic_core::MessageSink for Out<S> {
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
