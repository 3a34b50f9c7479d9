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

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Error::NonFinite { what, index } => write!(f, "{what}[{index}] is not a finite number"),
            Error::OutOfRange { what } => write!(f, "{what} is out of range"),
            Error::SizeMismatch {
                what,
                expected,
                found,
            } => {
                write!(f, "{what}: expected {expected}, found {found}")
            }
            Error::BadMagic => write!(f, "not a magic model file (bad magic bytes)"),
            Error::UnsupportedVersion { found, supported } => {
                write!(
                    f,
                    "model format version {found} is not supported (this build reads {supported})"
                )
            }
            Error::WrongProblem => write!(f, "model is for a different problem kind"),
            Error::CrcMismatch { stored, computed } => write!(
                f,
                "model file is corrupt: CRC stored {stored:#010x}, computed {computed:#010x}"
            ),
            Error::Truncated => write!(f, "model file is truncated"),
            Error::Decode => write!(f, "model file contents are malformed"),
            Error::InvalidModel(why) => write!(f, "invalid model: {why}"),
            Error::BufferTooSmall { needed } => write!(f, "buffer too small: {needed} needed"),
            Error::TooFewObservations { observed, needed } => write!(
                f,
                "too few observed channels: {observed} observed, at least {needed} needed"
            ),
        }
    }
}

#[cfg(feature = "std")]
extern crate std;

#[cfg(feature = "std")]
impl std::error::Error for Error {}
