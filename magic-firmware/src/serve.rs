//! The deployable program: the line protocol on UART0, the model from the flash slots, model
//! updates, the watchdog.
//!
//! Every line the host sends gets exactly one answer line, in order:
//!
//! | host sends | board answers |
//! |---|---|
//! | a day: `[YYYY-MM-DD,]v1,…,vN` | `<id>,<result>` or `<id>,error,<message>`: the result line of `magic_core::line` behind the id (8 hex digits, the model file's CRC-32) of the model that inverted it; `none,error,no model…` without one |
//! | `!model <size> <crc>` | `model,ready,<size>` (the target slot is erased) or `model,error,<why>` |
//! | `:<hex>` (model bytes) | `model,<bytes so far>`; after the last byte `model,ok,<id>` (switched) or `model,error,<why>` (the running model stays) |
//! | `!status` | `status,model=<id>,slot=…,reset=…,rx=…,slot_bytes=…,flash=…,statics=…,stack=…,stack_available=…[,sd=yes]` |
//! | `!reset` | `reset`, then a system reset |
//!
//! Lines the board sends on its own start with `!`: `!ready,…` (the fields of `status`) after
//! every start, `!model,error,<why>` when an upload is abandoned — no upload line for
//! [`upload::TIMEOUT_MS`], or a line that is not model data in the middle of one (that line is
//! then answered as usual) — and `!error,…` for lost input or a fault. The host may send ahead
//! of the answers up to [`uart::RX_BUF`] bytes of unanswered lines (announced as `rx=`).
//!
//! Built with the feature `sd`, every result line also carries the variables' standard
//! deviations (as `magic invert --sd` writes them) and the status says `sd=yes`.

use crate::console::{Lines, Out};
use crate::flash::RamFlash;
use crate::line::{Line, LINE_TOO_LONG};
use crate::reset::{self, Cause};
use crate::selfcheck::self_check;
use crate::slots::{Layout, Store};
use crate::text::{parse_record_bytes, write_hex8, write_result, write_u32};
use crate::upload::{self, Reject, Upload};
use crate::{ticks, uart, wdog, Linked};
use core::fmt::Write;
use magic_core::invert::{invert_into, Workspace};
use magic_core::line::LineError;
use magic_core::model_file::{Model, MAX_OBS};
use magic_core::Inversion;

/// Runs the board: never returns (a fault or `!reset` restarts it).
pub fn run() -> ! {
    let cause = reset::take();
    let mut out = Out::new();
    let (Some(cp), Some(ws), Some(inv), Some(lines), Some(models)) = (
        cortex_m::Peripherals::take(),
        workspace(),
        inversion(),
        lines(),
        models(),
    ) else {
        let _ = out.write_str("!error,start-up: state already taken");
        out.end_line();
        reset::request(Cause::Fault)
    };
    ticks::start(cp.SYST);
    uart::init();
    wdog::start();

    let layout = Layout::linked();
    let (start, end) = layout.region();
    #[cfg(feature = "sd")]
    let Some(sd) = crate::sd::state() else {
        let _ = out.write_str("!error,start-up: state already taken");
        out.end_line();
        reset::request(Cause::Fault)
    };
    let mut board = Board {
        models,
        ids: [0; 2],
        active: None,
        store: Store::open(RamFlash::new(start, end), layout),
        upload: None,
        cause,
        #[cfg(feature = "sd")]
        sd,
    };
    if layout.fits::<RamFlash>() {
        board.boot();
    } else {
        let _ = out.write_str("!error,the slot layout of memory-uart.x is not whole flash pages");
        out.end_line();
    }
    board.status(&mut out, "!ready");

    let mut lost = 0;
    loop {
        #[cfg(feature = "panic-canary")]
        if lost == u32::MAX {
            panic!("canary: a reachable panic for the panic-never check");
        }
        wdog::feed();
        let now = ticks::now_ms();
        if uart::lost() != lost {
            let n = uart::lost().wrapping_sub(lost);
            lost = uart::lost();
            lines.discard_partial();
            let _ = out.write_str("!error,input overrun: ");
            let _ = write_u32(&mut out, n);
            let _ = out.write_str(" bytes lost (more than rx= bytes sent ahead of the answers)");
            out.end_line();
        }
        match lines.poll() {
            Some(line) => board.answer(line, ws, inv, &mut out, now),
            None => {
                board.check_timeout(&mut out, now);
                uart::wait_for_input();
            }
        }
    }
}

/// Why a model could not be loaded from a slot.
enum LoadError {
    /// The slot is not there or smaller than the length.
    Slot,
    /// The model file's own CRC (its last four bytes) is not the expected id.
    Id { stored: u32, expected: u32 },
    /// `Model::decode`: magic, version, CRC, problem, sizes.
    Model(magic_core::Error),
    /// The int8 kernel check failed.
    SelfCheck(&'static str),
}

impl LoadError {
    fn describe(&self, out: &mut Out) {
        match self {
            LoadError::Slot => {
                let _ = out.write_str("slot: no such slot or length");
            }
            LoadError::Id { stored, expected } => {
                let _ = out.write_str("crc: the model's CRC-32 is ");
                let _ = write_hex8(out, *stored);
                let _ = out.write_str(", not the announced ");
                let _ = write_hex8(out, *expected);
            }
            LoadError::Model(e) => {
                let _ = out.write_str("model: ");
                e.describe(out);
            }
            LoadError::SelfCheck(what) => {
                let _ = out.write_str("self-check: ");
                let _ = out.write_str(what);
            }
        }
    }
}

/// The id of a model file: its last four bytes (the CRC-32 of everything before them).
fn trailer_id(bytes: &[u8]) -> u32 {
    match bytes {
        [.., a, b, c, d] => u32::from_le_bytes([*a, *b, *c, *d]),
        _ => 0,
    }
}

/// The board's state between lines.
struct Board {
    /// The decoded model of each slot (borrowing the slot's bytes); empty when not loaded.
    models: &'static mut [Model<'static>; 2],
    /// The id of each loaded model.
    ids: [u32; 2],
    /// The slot of the running model.
    active: Option<usize>,
    store: Store<RamFlash>,
    upload: Option<Upload>,
    cause: Cause,
    /// The standard deviations' working memory (feature `sd`).
    #[cfg(feature = "sd")]
    sd: &'static mut crate::sd::SdState,
}

impl Board {
    /// Runs the newest model of the slot headers whose slot holds it, intact.
    fn boot(&mut self) {
        for (page, rec) in self.store.candidates().into_iter().flatten() {
            if self.load(rec.slot, rec.len, rec.id).is_ok() {
                self.active = Some(rec.slot);
                self.store.set_in_use(page);
                return;
            }
        }
    }

    /// Decodes and checks the model of `slot` (`len` bytes, id `id`).
    fn load(&mut self, slot: usize, len: usize, id: u32) -> Result<(), LoadError> {
        let bytes = self.store.model_bytes(slot, len).ok_or(LoadError::Slot)?;
        let model = self.models.get_mut(slot).ok_or(LoadError::Slot)?;
        let stored = trailer_id(bytes);
        let result = if stored != id {
            Err(LoadError::Id {
                stored,
                expected: id,
            })
        } else {
            model
                .decode_in_place::<Linked>(bytes)
                .map_err(LoadError::Model)
                .and_then(|()| self_check(model).map_err(LoadError::SelfCheck))
        };
        match result {
            Ok(()) => {
                if let Some(i) = self.ids.get_mut(slot) {
                    *i = id;
                }
                Ok(())
            }
            Err(e) => {
                *model = Model::empty();
                Err(e)
            }
        }
    }

    fn write_id(&self, out: &mut Out) {
        match self.active.and_then(|a| self.ids.get(a)) {
            Some(&id) => {
                let _ = write_hex8(out, id);
            }
            None => {
                let _ = out.write_str("none");
            }
        }
    }

    /// Answers one line.
    fn answer(
        &mut self,
        line: Line<'_>,
        ws: &mut Workspace,
        inv: &mut Inversion<f32>,
        out: &mut Out,
        now: u32,
    ) {
        let text = match line {
            Line::Text(t) => t,
            Line::TooLong => {
                self.abandon(out, "interrupted by a line that is not model data");
                self.write_id(out);
                let _ = out.write_char(',');
                let _ = out.write_str(LINE_TOO_LONG);
                out.end_line();
                return;
            }
        };
        match text.first() {
            Some(b':') => self.data(text.get(1..).unwrap_or(&[]), out, now),
            Some(b'!') => self.command(text.get(1..).unwrap_or(&[]), out, now),
            _ => {
                self.abandon(out, "interrupted by a line that is not model data");
                self.day(text, ws, inv, out);
            }
        }
        out.end_line();
    }

    /// Inverts a day with the running model.
    fn day(&mut self, text: &[u8], ws: &mut Workspace, inv: &mut Inversion<f32>, out: &mut Out) {
        self.write_id(out);
        let _ = out.write_char(',');
        let Some(model) = self.active.and_then(|a| self.models.get(a)) else {
            let _ = out.write_str("error,no model: upload one with !model");
            return;
        };
        // (A loaded model has at most MAX_OBS channels; the clamp spares the slicing below its
        // panic paths.)
        let n_obs = model.n_obs().min(MAX_OBS);
        let mut obs = [0f32; MAX_OBS];
        let result =
            parse_record_bytes(text, model.needs_time(), &mut obs[..n_obs]).and_then(|day| {
                invert_into::<f32, Linked>(model, &obs[..n_obs], day, ws, inv)
                    .map(|()| day)
                    .map_err(LineError::Invert)
            });
        match result {
            Ok(_day) => {
                let _ = write_result(out, inv);
                #[cfg(feature = "sd")]
                crate::sd::write_sds(out, model, &obs[..n_obs], _day, inv, self.sd);
            }
            Err(e) => {
                let _ = out.write_str("error,");
                e.describe(out);
            }
        }
    }

    /// A `!` command.
    fn command(&mut self, text: &[u8], out: &mut Out, now: u32) {
        let (word, args) = match text.iter().position(|&b| b == b' ') {
            Some(i) => (
                text.get(..i).unwrap_or(&[]),
                text.get(i + 1..).unwrap_or(&[]),
            ),
            None => (text, &[][..]),
        };
        match word {
            b"model" => self.begin(args, out, now),
            b"status" => self.status(out, "status"),
            b"reset" => {
                let _ = out.write_str("reset");
                out.end_line();
                // Let the line leave the transmitter before the reset.
                let t = ticks::now_ms();
                while ticks::now_ms().wrapping_sub(t) < 3 * ticks::TICK_MS {
                    cortex_m::asm::wfi();
                }
                reset::request(Cause::Command)
            }
            #[cfg(feature = "hang-command")]
            b"hang" => {
                let _ = out.write_str("hang");
                out.end_line();
                #[allow(clippy::empty_loop)]
                loop {}
            }
            _ => {
                let _ = out.write_str("error,unknown command");
            }
        }
    }

    /// `!model <size> <crc>`: starts an upload into the slot that is not running.
    fn begin(&mut self, args: &[u8], out: &mut Out, now: u32) {
        self.abandon(out, "interrupted by a new !model");
        let _ = out.write_str("model,");
        let announced = upload::parse_command(args).and_then(|(size, id)| {
            Upload::check_size(size, self.store.slot_size()).map(|()| (size, id))
        });
        let (size, id) = match announced {
            Ok(v) => v,
            Err(r) => {
                let _ = out.write_str("error,");
                r.describe(out);
                return;
            }
        };
        let target = self.active.map_or(0, |a| a ^ 1);
        // Nothing may borrow the slot while it is rewritten.
        if let Some(m) = self.models.get_mut(target) {
            *m = Model::empty();
        }
        if let Err(e) = self.store.erase_slot(target, &mut wdog::feed) {
            let _ = out.write_str("error,");
            Reject::Flash(e).describe(out);
            return;
        }
        self.upload = Some(Upload::new(target, size, id, now));
        let _ = out.write_str("ready,");
        let _ = write_u32(out, size as u32);
    }

    /// `:<hex>`: model bytes.
    fn data(&mut self, hex: &[u8], out: &mut Out, now: u32) {
        let _ = out.write_str("model,");
        let Some(up) = self.upload.as_mut() else {
            let _ = out.write_str("error,");
            Reject::NotReceiving.describe(out);
            return;
        };
        match up.data(hex, &mut self.store, now) {
            Ok(false) => {
                let _ = write_u32(out, up.got as u32);
            }
            Ok(true) => {
                let (slot, size, id) = (up.slot, up.size, up.id);
                self.upload = None;
                self.finish(slot, size, id, out);
            }
            Err(r) => {
                self.upload = None;
                let _ = out.write_str("error,");
                r.describe(out);
            }
        }
    }

    /// All bytes are in: checks the model and switches to it, or keeps the running one.
    fn finish(&mut self, slot: usize, size: usize, id: u32, out: &mut Out) {
        if let Err(e) = self.load(slot, size, id) {
            let _ = out.write_str("error,");
            e.describe(out);
            return;
        }
        // The header record last: from here on (and after a reset) the board runs this model.
        if let Err(e) = self.store.commit(slot, size, id) {
            if let Some(m) = self.models.get_mut(slot) {
                *m = Model::empty();
            }
            let _ = out.write_str("error,");
            Reject::Flash(e).describe(out);
            return;
        }
        self.active = Some(slot);
        let _ = out.write_str("ok,");
        let _ = write_hex8(out, id);
    }

    /// Ends an upload in progress, if any, with an unsolicited `!model,error,…` line.
    fn abandon(&mut self, out: &mut Out, why: &str) {
        let Some(up) = self.upload.take() else {
            return;
        };
        let _ = out.write_str("!model,error,");
        let _ = out.write_str(why);
        let _ = out.write_str(" after ");
        let _ = write_u32(out, up.got as u32);
        let _ = out.write_str(" of ");
        let _ = write_u32(out, up.size as u32);
        let _ = out.write_str(" bytes");
        out.end_line();
    }

    fn check_timeout(&mut self, out: &mut Out, now: u32) {
        if self.upload.as_ref().is_some_and(|u| u.timed_out(now)) {
            self.abandon(out, "timed out");
        }
    }

    /// The status line (`tag` is `status` or `!ready`), without its end for `status`.
    fn status(&self, out: &mut Out, tag: &str) {
        let mem = crate::mem::memory();
        let _ = out.write_str(tag);
        let _ = out.write_str(",model=");
        self.write_id(out);
        let _ = out.write_str(",slot=");
        match self.active {
            Some(a) => {
                let _ = write_u32(out, a as u32);
            }
            None => {
                let _ = out.write_str("none");
            }
        }
        let _ = out.write_str(",reset=");
        let _ = out.write_str(self.cause.name());
        for (key, v) in [
            (",rx=", uart::RX_BUF),
            (",slot_bytes=", self.store.slot_size()),
            (",flash=", mem.flash_used),
            (",statics=", mem.statics),
            (",stack=", mem.stack_used),
            (",stack_available=", mem.stack_size),
        ] {
            let _ = out.write_str(key);
            let _ = write_u32(out, v as u32);
        }
        // Every result line carries the variables' standard deviations too.
        #[cfg(feature = "sd")]
        let _ = out.write_str(",sd=yes");
        if tag.starts_with('!') {
            out.end_line();
        }
    }
}

/// The inversion's working memory, in a static.
#[inline(never)]
fn workspace() -> Option<&'static mut Workspace> {
    cortex_m::singleton!(: Workspace = Workspace::default())
}

/// The result of an inversion, in a static.
#[inline(never)]
fn inversion() -> Option<&'static mut Inversion<f32>> {
    cortex_m::singleton!(: Inversion<f32> = Inversion::empty())
}

/// The input line buffer, in a static.
#[inline(never)]
fn lines() -> Option<&'static mut Lines> {
    cortex_m::singleton!(: Lines = Lines::new())
}

/// The decoded models of the two slots, in a static.
#[inline(never)]
fn models() -> Option<&'static mut [Model<'static>; 2]> {
    cortex_m::singleton!(: [Model<'static>; 2] = [Model::empty(), Model::empty()])
}
