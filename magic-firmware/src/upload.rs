//! A model upload in progress (the deployable build): the `!model <size> <crc>` command, then
//! data lines `:<hex>` whose bytes are written into the target slot as they arrive.
//!
//! Hexadecimal lines rather than raw bytes: the link stays a line protocol (every line the host
//! sends gets one answer, so the host can pace itself by the board's receive buffer), the
//! bytes pass any serial link, terminal program or line discipline unchanged (no byte is a
//! newline, XON/XOFF or a control character), and a line that is not data — a day sent after
//! an upload was cut off — is recognised at once instead of being swallowed as model bytes. It
//! costs twice the bytes on the wire (38 KB for a 19 KB model: 3.3 s at 115 200 baud).
//!
//! Bytes are programmed in chunks of [`CHUNK`] as they arrive (the last one padded with `0xFF`,
//! which leaves erased flash as it is); the checks of the whole model follow once all `size`
//! bytes are in (see `serve`).

use crate::flash::{Flash, FlashError};
use crate::slots::Store;
use crate::text::write_u32;
use core::fmt::Write;

/// Bytes programmed at once (a multiple of every supported program unit).
pub const CHUNK: usize = 32;
/// Milliseconds without an upload line after which the upload is abandoned.
pub const TIMEOUT_MS: u32 = 2000;
/// Smallest model file: header (10 bytes) and CRC (4 bytes).
const MIN_SIZE: usize = 14;

/// Why an upload was refused or ended.
#[derive(Clone, Copy)]
pub enum Reject {
    /// The command's arguments are not `<size> <crc>`.
    Usage,
    /// The announced size is not a model's.
    TooSmall(usize),
    /// The announced size exceeds a slot.
    TooLarge {
        /// Announced bytes.
        size: usize,
        /// Bytes per slot.
        slot: usize,
    },
    /// A data line without an upload in progress.
    NotReceiving,
    /// A data line that is not an even number of hex digits.
    BadHex,
    /// More bytes than announced.
    TooMany(usize),
    /// Erasing or programming the slot failed.
    Flash(FlashError),
}

impl Reject {
    /// Writes the reason (no newline).
    pub fn describe<W: Write>(&self, w: &mut W) {
        let _ = match *self {
            Reject::Usage => w.write_str("usage: !model <size in bytes> <CRC-32, 8 hex digits>"),
            Reject::TooSmall(n) => {
                let _ = w.write_str("a model file has at least 14 bytes, not ");
                write_u32(w, n as u32)
            }
            Reject::TooLarge { size, slot } => {
                let _ = w.write_str("too large: ");
                let _ = write_u32(w, size as u32);
                let _ = w.write_str(" bytes, a slot holds ");
                write_u32(w, slot as u32)
            }
            Reject::NotReceiving => w.write_str("model data without !model"),
            Reject::BadHex => w.write_str("model data is not an even number of hex digits"),
            Reject::TooMany(n) => {
                let _ = w.write_str("more bytes than the announced ");
                write_u32(w, n as u32)
            }
            Reject::Flash(e) => w.write_str(e.message()),
        };
    }
}

/// Reads the arguments of `!model`: `<size> <crc>` (decimal bytes, 8 hex digits with an
/// optional `0x`), separated by spaces.
pub fn parse_command(args: &[u8]) -> Result<(usize, u32), Reject> {
    let mut words = args.split(|&b| b == b' ').filter(|w| !w.is_empty());
    let (Some(size), Some(crc), None) = (words.next(), words.next(), words.next()) else {
        return Err(Reject::Usage);
    };
    let size = parse_decimal(size).ok_or(Reject::Usage)?;
    let crc = crc.strip_prefix(b"0x").unwrap_or(crc);
    if crc.len() != 8 {
        return Err(Reject::Usage);
    }
    let mut id = 0u32;
    for &c in crc {
        id = (id << 4) | u32::from(hex_digit(c).ok_or(Reject::Usage)?);
    }
    Ok((size, id))
}

fn parse_decimal(b: &[u8]) -> Option<usize> {
    if b.is_empty() || b.len() > 9 {
        return None;
    }
    b.iter().try_fold(0usize, |n, &c| {
        c.is_ascii_digit().then(|| n * 10 + usize::from(c - b'0'))
    })
}

fn hex_digit(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

/// An upload being received into a slot.
pub struct Upload {
    /// Target slot.
    pub slot: usize,
    /// Announced size, bytes.
    pub size: usize,
    /// Announced model id (CRC-32).
    pub id: u32,
    /// Bytes received so far.
    pub got: usize,
    chunk: [u8; CHUNK],
    n: usize,
    /// When the last upload line arrived (ms).
    last_ms: u32,
}

impl Upload {
    /// Checks the announced size against a slot of `slot_size` bytes.
    pub fn check_size(size: usize, slot_size: usize) -> Result<(), Reject> {
        if size < MIN_SIZE {
            return Err(Reject::TooSmall(size));
        }
        if size > slot_size {
            return Err(Reject::TooLarge {
                size,
                slot: slot_size,
            });
        }
        Ok(())
    }

    /// An upload of `size` bytes with id `id` into the (erased) slot `slot`, started at `now`.
    pub fn new(slot: usize, size: usize, id: u32, now: u32) -> Upload {
        Upload {
            slot,
            size,
            id,
            got: 0,
            chunk: [0xFF; CHUNK],
            n: 0,
            last_ms: now,
        }
    }

    /// Takes a data line (the hex digits after `:`); `Ok(true)` once all bytes are written.
    pub fn data<F: Flash>(
        &mut self,
        hex: &[u8],
        store: &mut Store<F>,
        now: u32,
    ) -> Result<bool, Reject> {
        self.last_ms = now;
        if hex.len() % 2 != 0 {
            return Err(Reject::BadHex);
        }
        for pair in hex.chunks_exact(2) {
            let (Some(&h), Some(&l)) = (pair.first(), pair.get(1)) else {
                return Err(Reject::BadHex);
            };
            let (Some(h), Some(l)) = (hex_digit(h), hex_digit(l)) else {
                return Err(Reject::BadHex);
            };
            if self.got >= self.size {
                return Err(Reject::TooMany(self.size));
            }
            if let Some(b) = self.chunk.get_mut(self.n) {
                *b = (h << 4) | l;
            }
            self.n += 1;
            self.got += 1;
            if self.n == CHUNK {
                self.flush(store)?;
            }
        }
        if self.got == self.size {
            self.flush(store)?;
            return Ok(true);
        }
        Ok(false)
    }

    /// Programs the chunk collected so far (padded with `0xFF`).
    fn flush<F: Flash>(&mut self, store: &mut Store<F>) -> Result<(), Reject> {
        if self.n == 0 {
            return Ok(());
        }
        // (`got` counts the bytes of this chunk too.)
        let offset = self.got - self.n;
        let result = store.program_slot(self.slot, offset, &self.chunk);
        self.chunk = [0xFF; CHUNK];
        self.n = 0;
        result.map_err(Reject::Flash)
    }

    /// Whether no upload line came for [`TIMEOUT_MS`].
    pub fn timed_out(&self, now: u32) -> bool {
        now.wrapping_sub(self.last_ms) > TIMEOUT_MS
    }
}
