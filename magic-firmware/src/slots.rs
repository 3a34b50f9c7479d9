//! The two model slots and their header (the deployable build): where uploaded models live in
//! flash, and which one the board runs after a reset.
//!
//! `memory-uart.x` places, after the program image, two slots of equal size (`SLOTS`) and two
//! header pages (`HEADER`), and exports their addresses and sizes as linker symbols. None of it
//! is part of the program image: a board keeps what was written there across resets, and QEMU,
//! which rewrites the image's bytes from the ELF at every system reset, leaves it alone too.
//!
//! A header record is seven little-endian words at the start of a header page:
//!
//! ```text
//! MAGIC | FORMAT | seq | slot | model length | model id (its CRC-32) | CRC-32 of the six words before
//! ```
//!
//! The valid record with the highest `seq` names the model the board runs. A switch writes the
//! new model into the other slot, checks it, and only then writes a record with `seq + 1` into
//! the header page that does not hold the record in use — last. A power loss or reset at any
//! point leaves the previous record standing (a half-written record fails its CRC), and at
//! start-up a record whose slot does not hold the model it names is passed over for the older
//! one.

use crate::flash::{self, Flash, FlashError};

/// First word of a header record ("MGSH").
const MAGIC: u32 = u32::from_le_bytes(*b"MGSH");
/// Version of the record's layout.
const FORMAT: u32 = 1;
/// Bytes of a record (seven words) as written: padded to 32 with `0xFF`.
const RECORD: usize = 32;

const CRC: crc::Crc<u32, crc::NoTable> = crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);

extern "C" {
    static __model_slots: u8;
    static __model_slot_size: u8;
    static __slot_headers: u8;
    static __slot_header_size: u8;
}

/// Where the slots and header pages are (from `memory-uart.x`).
#[derive(Clone, Copy)]
pub struct Layout {
    /// Address of slot 0; slot 1 follows it.
    pub slots: usize,
    /// Bytes per slot: the largest model the board accepts.
    pub slot_size: usize,
    /// Address of header page 0; page 1 follows it.
    pub headers: usize,
    /// Bytes per header page.
    pub header_size: usize,
}

impl Layout {
    /// The layout the firmware was linked with.
    pub fn linked() -> Layout {
        // (Linker symbols: their addresses are the values.)
        Layout {
            slots: core::ptr::addr_of!(__model_slots) as usize,
            slot_size: core::ptr::addr_of!(__model_slot_size) as usize,
            headers: core::ptr::addr_of!(__slot_headers) as usize,
            header_size: core::ptr::addr_of!(__slot_header_size) as usize,
        }
    }

    /// Whether slots and header pages are whole pages of `F` and at least a record long.
    pub fn fits<F: Flash>(&self) -> bool {
        let aligned = |v: usize| v % F::PAGE == 0;
        aligned(self.slots)
            && aligned(self.slot_size)
            && aligned(self.headers)
            && aligned(self.header_size)
            && self.header_size >= RECORD
            && self.slot_size > 0
    }

    /// First and one-past-last address of the writable region (slots, then header pages).
    pub fn region(&self) -> (usize, usize) {
        (self.slots, self.headers + 2 * self.header_size)
    }

    fn slot(&self, k: usize) -> usize {
        self.slots + k * self.slot_size
    }

    fn page(&self, k: usize) -> usize {
        self.headers + k * self.header_size
    }
}

/// A header record: slot `slot` holds `len` bytes of the model with id `id`.
#[derive(Clone, Copy)]
pub struct Record {
    /// Sequence number: the highest valid one is the newest.
    pub seq: u32,
    /// Slot (0 or 1).
    pub slot: usize,
    /// Model file length, bytes.
    pub len: usize,
    /// Model id: the CRC-32 at the end of the model file.
    pub id: u32,
}

impl Record {
    fn words(&self) -> [u32; 6] {
        [
            MAGIC,
            FORMAT,
            self.seq,
            self.slot as u32,
            self.len as u32,
            self.id,
        ]
    }

    fn bytes(&self) -> [u8; RECORD] {
        let mut b = [0xFF; RECORD];
        let words = self.words();
        let mut crc = CRC.digest();
        for (chunk, w) in b.chunks_exact_mut(4).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
            crc.update(chunk);
        }
        if let Some(c) = b.get_mut(24..28) {
            c.copy_from_slice(&crc.finalize().to_le_bytes());
        }
        b
    }

    fn parse(b: &[u8]) -> Option<Record> {
        let mut w = [0u32; 7];
        for (v, c) in w.iter_mut().zip(b.chunks_exact(4)) {
            if let Ok(c) = <[u8; 4]>::try_from(c) {
                *v = u32::from_le_bytes(c);
            }
        }
        let [magic, format, seq, slot, len, id, crc] = w;
        let ok = magic == MAGIC
            && format == FORMAT
            && slot < 2
            && b.get(..24).is_some_and(|words| CRC.checksum(words) == crc);
        ok.then_some(Record {
            seq,
            slot: slot as usize,
            len: len as usize,
            id,
        })
    }
}

/// The slots and header pages of a board, written through `F`.
pub struct Store<F: Flash> {
    flash: F,
    layout: Layout,
    /// The valid record of each header page.
    records: [Option<Record>; 2],
    /// The header page whose record the running model came from.
    in_use: Option<usize>,
}

impl<F: Flash> Store<F> {
    /// Reads both header pages.
    pub fn open(flash: F, layout: Layout) -> Store<F> {
        let read = |k: usize| Record::parse(flash::read(layout.page(k), RECORD));
        Store {
            records: [read(0), read(1)],
            flash,
            layout,
            in_use: None,
        }
    }

    /// Bytes per slot.
    pub fn slot_size(&self) -> usize {
        self.layout.slot_size
    }

    /// The valid records, newest first, with their header page.
    pub fn candidates(&self) -> [Option<(usize, Record)>; 2] {
        let [a, b] = self.records;
        let a = a.map(|r| (0, r));
        let b = b.map(|r| (1, r));
        match (a, b) {
            (Some(x), Some(y)) if y.1.seq > x.1.seq => [b, a],
            _ => [a, b],
        }
    }

    /// Notes that the running model came from the record of header page `page`.
    pub fn set_in_use(&mut self, page: usize) {
        self.in_use = Some(page);
    }

    /// The first `len` bytes of slot `slot`, if that is within a slot.
    pub fn model_bytes(&self, slot: usize, len: usize) -> Option<&'static [u8]> {
        (slot < 2 && len <= self.layout.slot_size).then(|| flash::read(self.layout.slot(slot), len))
    }

    /// Erases slot `slot` page by page, calling `between` after each page (to feed the
    /// watchdog: a board's page erase can take tens of milliseconds). The caller makes sure
    /// nothing of that slot is in use.
    pub fn erase_slot(&mut self, slot: usize, between: &mut dyn FnMut()) -> Result<(), FlashError> {
        if slot >= 2 {
            return Err(FlashError::OutOfRange);
        }
        let start = self.layout.slot(slot);
        for addr in (start..start + self.layout.slot_size).step_by(F::PAGE) {
            self.flash.erase_page(addr)?;
            between();
        }
        Ok(())
    }

    /// Programs `data` at `offset` of slot `slot` (offset and length multiples of the program
    /// unit, within the slot).
    pub fn program_slot(
        &mut self,
        slot: usize,
        offset: usize,
        data: &[u8],
    ) -> Result<(), FlashError> {
        if slot >= 2 || offset + data.len() > self.layout.slot_size {
            return Err(FlashError::OutOfRange);
        }
        self.flash.program(self.layout.slot(slot) + offset, data)
    }

    /// Makes slot `slot`, holding `len` bytes of the model `id`, the one the board runs from
    /// now on and after a reset: writes a record newer than every valid one into the header
    /// page that does not hold the record in use. Written last, after the model was checked.
    pub fn commit(&mut self, slot: usize, len: usize, id: u32) -> Result<(), FlashError> {
        let seq = self
            .records
            .iter()
            .flatten()
            .map(|r| r.seq)
            .max()
            .map_or(1, |s| s.wrapping_add(1));
        let page = match self.in_use {
            Some(p) => p ^ 1,
            None => 0,
        };
        let record = Record { seq, slot, len, id };
        let addr = self.layout.page(page & 1);
        self.flash.erase_page(addr)?;
        self.flash.program(addr, &record.bytes())?;
        // The record as read back from flash is what counts.
        let written = Record::parse(flash::read(addr, RECORD)).ok_or(FlashError::Verify)?;
        if let Some(r) = self.records.get_mut(page & 1) {
            *r = Some(written);
        }
        self.in_use = Some(page & 1);
        Ok(())
    }
}
