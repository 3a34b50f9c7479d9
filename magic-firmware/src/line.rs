//! One input line as the firmware reads it (from semihosting stdin or from the UART), and the
//! longest line it accepts.

/// Longest input line accepted (bytes, without the newline): 96 channels of 10 characters fit.
pub const LINE_MAX: usize = 1024;

/// The answer to an input line longer than [`LINE_MAX`] (a constant: no formatting code).
pub const LINE_TOO_LONG: &str = "error,line longer than 1024 bytes";
const _: () = assert!(LINE_MAX == 1024, "update LINE_TOO_LONG");

/// One input line as read.
pub enum Line<'a> {
    /// The bytes of the line without its end (`\n`, `\r\n`).
    Text(&'a [u8]),
    /// The line was longer than [`LINE_MAX`] (the rest of it was skipped).
    TooLong,
}

/// The bytes of a line without a trailing `\r` (a `\r\n` line end).
pub fn strip_cr(bytes: &[u8]) -> &[u8] {
    match bytes {
        [rest @ .., b'\r'] => rest,
        _ => bytes,
    }
}
