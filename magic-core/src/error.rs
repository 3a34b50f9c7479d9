//! The one error type of the core: a plain enum, `Copy`, with a human-readable `Display`.

use core::fmt;

/// Everything that can go wrong in the core. No function of this crate panics on input; each
/// fallible step returns one of these.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// An input value was NaN or infinite where a finite number was needed.
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Index of the offending element.
        index: usize,
    },
    /// A value lies outside the range the operation accepts.
    OutOfRange {
        /// Which value.
        what: &'static str,
    },
    /// A slice, table or layer has the wrong length.
    SizeMismatch {
        /// What was measured.
        what: &'static str,
        /// The length required.
        expected: usize,
        /// The length found.
        found: usize,
    },
    /// The bytes do not start with the model-file magic `MAGC`.
    BadMagic,
    /// The model file's format version is not the one this build reads.
    UnsupportedVersion {
        /// Version in the file.
        found: u16,
        /// Version this build reads.
        supported: u16,
    },
    /// The model was made for another problem (e.g. an RTM model given to the Mogi firmware).
    WrongProblem,
    /// The CRC-32 stored in the file does not match its contents (corruption, flipped bits).
    CrcMismatch {
        /// CRC stored at the end of the file.
        stored: u32,
        /// CRC computed over the contents.
        computed: u32,
    },
    /// The bytes end before the structure does.
    Truncated,
    /// The contents could not be decoded (the serialised structure is malformed).
    Decode,
    /// The model decodes but is inconsistent (e.g. layer sizes that do not chain).
    InvalidModel(&'static str),
    /// A buffer the caller provided is too small.
    BufferTooSmall {
        /// Bytes or elements needed.
        needed: usize,
    },
    /// Too few channels were observed to determine the unknowns.
    TooFewObservations {
        /// Channels observed.
        observed: usize,
        /// Channels needed at least.
        needed: usize,
    },
}

/// `Ok` when a length is the one required, else [`Error::SizeMismatch`].
pub(crate) fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), Error> {
    if found == expected {
        Ok(())
    } else {
        Err(Error::SizeMismatch {
            what,
            expected,
            found,
        })
    }
}

/// Where [`Error::describe`] writes a message: text pieces and numbers, so that a target
/// without `core::fmt` (the firmware keeps its flash small) prints the same words as `Display`.
pub trait MessageSink {
    /// Appends text.
    fn text(&mut self, s: &str);
    /// Appends an unsigned integer in decimal.
    fn number(&mut self, n: u32);
    /// Appends a 32-bit value as `0x` and eight hex digits (like `{:#010x}`).
    fn hex(&mut self, n: u32);
}

/// Sizes beyond `u32` are printed saturated (no model or buffer of this crate comes near).
fn n32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

impl Error {
    /// Writes the human-readable message, the one `Display` prints, piece by piece.
    ///
    /// ```
    /// use magic_core::{Error, MessageSink};
    /// struct S(String);
    /// impl MessageSink for S {
    ///     fn text(&mut self, s: &str) { self.0.push_str(s) }
    ///     fn number(&mut self, n: u32) { self.0.push_str(&n.to_string()) }
    ///     fn hex(&mut self, n: u32) { self.0.push_str(&format!("{n:#010x}")) }
    /// }
    /// let e = Error::SizeMismatch { what: "observations", expected: 36, found: 35 };
    /// let mut s = S(String::new());
    /// e.describe(&mut s);
    /// assert_eq!(s.0, "observations: expected 36, found 35");
    /// assert_eq!(s.0, e.to_string());
    /// ```
    pub fn describe<S: MessageSink + ?Sized>(&self, s: &mut S) {
        match *self {
            Error::NonFinite { what, index } => {
                s.text(what);
                s.text("[");
                s.number(n32(index));
                s.text("] is not a finite number");
            }
            Error::OutOfRange { what } => {
                s.text(what);
                s.text(" is out of range");
            }
            Error::SizeMismatch {
                what,
                expected,
                found,
            } => {
                s.text(what);
                s.text(": expected ");
                s.number(n32(expected));
                s.text(", found ");
                s.number(n32(found));
            }
            Error::BadMagic => s.text("not a magic model file (bad magic bytes)"),
            Error::UnsupportedVersion { found, supported } => {
                s.text("model format version ");
                s.number(u32::from(found));
                s.text(" is not supported (this build reads ");
                s.number(u32::from(supported));
                s.text(")");
            }
            Error::WrongProblem => s.text("model is for a different problem kind"),
            Error::CrcMismatch { stored, computed } => {
                s.text("model file is corrupt: CRC stored ");
                s.hex(stored);
                s.text(", computed ");
                s.hex(computed);
            }
            Error::Truncated => s.text("model file is truncated"),
            Error::Decode => s.text("model file contents are malformed"),
            Error::InvalidModel(why) => {
                s.text("invalid model: ");
                s.text(why);
            }
            Error::BufferTooSmall { needed } => {
                s.text("buffer too small: ");
                s.number(n32(needed));
                s.text(" needed");
            }
            Error::TooFewObservations { observed, needed } => {
                s.text("too few observed channels: ");
                s.number(n32(observed));
                s.text(" observed, at least ");
                s.number(n32(needed));
                s.text(" needed");
            }
        }
    }
}

/// `Display` through a `describe` function: one text for every target.
pub(crate) struct FmtSink<'a, 'b> {
    f: &'a mut fmt::Formatter<'b>,
    result: fmt::Result,
}

impl<'a, 'b> FmtSink<'a, 'b> {
    /// Runs `describe` into the formatter.
    pub(crate) fn display(
        f: &'a mut fmt::Formatter<'b>,
        describe: impl FnOnce(&mut Self),
    ) -> fmt::Result {
        let mut sink = FmtSink { f, result: Ok(()) };
        describe(&mut sink);
        sink.result
    }
}

impl MessageSink for FmtSink<'_, '_> {
    fn text(&mut self, s: &str) {
        if self.result.is_ok() {
            self.result = self.f.write_str(s);
        }
    }
    fn number(&mut self, n: u32) {
        if self.result.is_ok() {
            self.result = write!(self.f, "{n}");
        }
    }
    fn hex(&mut self, n: u32) {
        if self.result.is_ok() {
            self.result = write!(self.f, "{n:#010x}");
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        FmtSink::display(f, |s| self.describe(s))
    }
}

#[cfg(feature = "std")]
extern crate std;

#[cfg(feature = "std")]
impl std::error::Error for Error {}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::Error;
    use std::string::ToString;

    /// Every message, as users see it.
    #[test]
    fn messages() {
        let cases = [
            (
                Error::NonFinite {
                    what: "observations",
                    index: 7,
                },
                "observations[7] is not a finite number",
            ),
            (Error::OutOfRange { what: "depth" }, "depth is out of range"),
            (
                Error::SizeMismatch {
                    what: "stations",
                    expected: 12,
                    found: 11,
                },
                "stations: expected 12, found 11",
            ),
            (Error::BadMagic, "not a magic model file (bad magic bytes)"),
            (
                Error::UnsupportedVersion {
                    found: 9,
                    supported: 5,
                },
                "model format version 9 is not supported (this build reads 5)",
            ),
            (Error::WrongProblem, "model is for a different problem kind"),
            (
                Error::CrcMismatch {
                    stored: 0xDEAD_BEEF,
                    computed: 0x1F,
                },
                "model file is corrupt: CRC stored 0xdeadbeef, computed 0x0000001f",
            ),
            (Error::Truncated, "model file is truncated"),
            (Error::Decode, "model file contents are malformed"),
            (Error::InvalidModel("no layers"), "invalid model: no layers"),
            (
                Error::BufferTooSmall { needed: 300 },
                "buffer too small: 300 needed",
            ),
            (
                Error::TooFewObservations {
                    observed: 3,
                    needed: 4,
                },
                "too few observed channels: 3 observed, at least 4 needed",
            ),
            (
                Error::BufferTooSmall { needed: usize::MAX },
                "buffer too small: 4294967295 needed",
            ),
        ];
        for (e, want) in cases {
            assert_eq!(e.to_string(), want);
        }
    }
}
