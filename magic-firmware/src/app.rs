//! The program: decode the embedded model, check the int8 kernel, stream lines through the
//! inversion, print the cost figures.

use crate::cost::{Clock, Stat};
use crate::io::{Out, Stdin};
use crate::line::{Line, LINE_TOO_LONG};
use crate::selfcheck::self_check;
use crate::text::{parse_record_bytes, write_result};
use crate::Linked;
use core::fmt::Write;
use magic_core::invert::{invert_probed, Part, Probe, Workspace};
use magic_core::line::LineError;
use magic_core::model_file::{Model, MAX_OBS};
use magic_core::{Flags, Inversion};

/// Word alignment for the embedded model file: the exporter aligns the int8 weights within the
/// file, so that the `SMLAD` kernel can load them with `LDM`.
#[repr(C, align(4))]
struct Aligned<B: ?Sized>(B);

static ALIGNED: &Aligned<[u8]> =
    &Aligned(*include_bytes!(concat!(env!("OUT_DIR"), "/model.magic")));

/// The model file named by `MAGIC_MODEL` at build time (see `build.rs`), word aligned.
static MODEL: &[u8] = &ALIGNED.0;

/// Runs the firmware; `true` for success (exit 0).
///
/// The large state (model, working memory, input buffer: about 6.5 KB) lives in statics, each
/// created in its own short-lived function, so that the stack holds only what one inversion needs.
pub fn run() -> bool {
    let mut out = Out::new();
    let (Some(cp), Some(ws), Some(stdin), Some(inv)) = (
        cortex_m::Peripherals::take(),
        workspace(),
        stdin(),
        inversion(),
    ) else {
        let _ = out.write_str("error,start-up: state already taken");
        out.end_line();
        return false;
    };
    #[cfg(feature = "sd")]
    let Some(sd_state) = crate::sd::state() else {
        return false;
    };
    let clock = Clock::start(cp.SYST);
    let Some(model) = start_model(&mut out) else {
        return false;
    };

    // (A validated model has at most MAX_OBS channels; the clamp spares the slicing below its
    // panic paths.)
    let n_obs = model.n_obs().min(MAX_OBS);
    // Models with time-dependent effects read a leading date on every line.
    let with_date = model.needs_time();
    let mut obs = [0f32; MAX_OBS];
    let mut total = Stat::default();
    let mut parts = [Stat::default(); 3];
    let mut missing = Stat::default();
    let mut parse = Stat::default();
    #[cfg(feature = "sd")]
    let mut sd_cost = Stat::default();
    let mut lines = 0u32;
    let mut errors = 0u32;
    while let Some(line) = stdin.next_line() {
        lines += 1;
        #[cfg(feature = "panic-canary")]
        if lines == u32::MAX {
            panic!("canary: a reachable panic for the panic-never check");
        }
        let Line::Text(text) = line else {
            errors += 1;
            let _ = out.write_str(LINE_TOO_LONG);
            out.end_line();
            continue;
        };
        let t0 = clock.now();
        let parsed = parse_record_bytes(text, with_date, &mut obs[..n_obs]);
        parse.add(clock.since(t0));
        #[cfg(feature = "sd")]
        let day = parsed.as_ref().ok().copied().unwrap_or(f64::NAN);
        let mut timing = Timing {
            clock: &clock,
            start: 0,
            parts: [0; 3],
        };
        let result = parsed.and_then(|day| {
            let t = clock.now();
            let r =
                invert_probed::<f32, Linked, _>(model, &obs[..n_obs], day, ws, inv, &mut timing);
            let dt = clock.since(t);
            r.map(|()| dt).map_err(LineError::Invert)
        });
        match result {
            Ok(dt) => {
                if inv.flags.has(Flags::MISSING) {
                    missing.add(dt);
                } else {
                    total.add(dt);
                    for (s, &t) in parts.iter_mut().zip(&timing.parts) {
                        s.add(t);
                    }
                }
                let _ = write_result(&mut out, inv);
                #[cfg(feature = "sd")]
                {
                    let t = clock.now();
                    crate::sd::write_sds(&mut out, model, &obs[..n_obs], day, inv, sd_state);
                    sd_cost.add(clock.since(t));
                }
            }
            Err(e) => {
                errors += 1;
                // As `magic_core::line::write_error` writes it, without `core::fmt`.
                let _ = out.write_str("error,");
                e.describe(&mut out);
            }
        }
        out.end_line();
    }

    // The stack high-water mark of the whole run.
    let mem = crate::mem::memory();
    let calib = clock.calibrate(10_000);

    let _ =
        out.write_str("# magic-firmware cost: instructions by QEMU -icount shift=0 and SysTick");
    out.end_line();
    kv(&mut out, "lines", lines);
    kv(&mut out, "errors", errors);
    kv(&mut out, "inversions_complete", total.n);
    kv(&mut out, "instructions_per_inversion", total.mean());
    kv(&mut out, "instructions_per_inversion_min", total.min);
    kv(&mut out, "instructions_per_inversion_max", total.max);
    kv(&mut out, "inversions_with_missing", missing.n);
    let key = "instructions_per_inversion_with_missing";
    kv(&mut out, key, missing.mean());
    kv(&mut out, "instructions_parse_line", parse.mean());
    #[cfg(feature = "sd")]
    kv(&mut out, "instructions_standard_deviations", sd_cost.mean());
    let [enc, mogi, corr] = parts;
    kv(&mut out, "instructions_encoder", enc.mean());
    kv(&mut out, "instructions_mogi", mogi.mean());
    kv(&mut out, "instructions_correction", corr.mean());
    kv(&mut out, "clock_calibration_permille", calib);
    if !(990..=1010).contains(&calib) {
        let _ = out.write_str(
            "# warning=SysTick does not count instructions (QEMU needs -icount shift=0)",
        );
        out.end_line();
    }
    kv(&mut out, "stack_bytes", mem.stack_used as u32);
    kv(&mut out, "stack_available_bytes", mem.stack_size as u32);
    kv(&mut out, "statics_bytes", mem.statics as u32);
    kv(&mut out, "flash_bytes", mem.flash_used as u32);
    kv(&mut out, "model_bytes", MODEL.len() as u32);
    if mem.stack_used >= mem.stack_size {
        let _ = out.write_str("# error=stack overflow");
        out.end_line();
        return false;
    }
    true
}

/// Decodes the embedded model and self-checks the int8 kernel on it; `None` (after an error
/// line, if there is something to say) when either fails.
fn start_model(out: &mut Out) -> Option<&'static Model<'static>> {
    let model = match load_model() {
        Some(Ok(m)) => m,
        Some(Err(e)) => {
            let _ = out.write_str("error,model: ");
            e.describe(out);
            out.end_line();
            return None;
        }
        None => return None,
    };
    if let Err(what) = self_check(model) {
        let _ = out.write_str("error,self-check: ");
        let _ = out.write_str(what);
        out.end_line();
        return None;
    }
    Some(model)
}

/// The inversion's working memory, in a static.
#[inline(never)]
fn workspace() -> Option<&'static mut Workspace> {
    cortex_m::singleton!(: Workspace = Workspace::default())
}

/// The result of an inversion (written in place by `invert_into`), in a static.
#[inline(never)]
fn inversion() -> Option<&'static mut Inversion<f32>> {
    cortex_m::singleton!(: Inversion<f32> = Inversion::empty())
}

/// The input reader and its line buffer, in a static.
#[inline(never)]
fn stdin() -> Option<&'static mut Stdin> {
    cortex_m::singleton!(: Stdin = Stdin::open())
}

/// Decodes the embedded model in place into a static (Mogi models only unless the feature `rtm`
/// links the RTM forward model): no copy of the decoded model on the stack.
#[inline(never)]
fn load_model() -> Option<Result<&'static Model<'static>, magic_core::Error>> {
    let slot: &'static mut Model<'static> =
        cortex_m::singleton!(: Model<'static> = Model::empty())?;
    Some(slot.decode_in_place::<Linked>(MODEL).map(|()| &*slot))
}

/// Writes a report line `# key=value` (one non-generic call per figure keeps the report small).
#[inline(never)]
fn kv(out: &mut Out, key: &str, v: u32) {
    let _ = out.write_str("# ");
    let _ = out.write_str(key);
    let _ = out.write_char('=');
    let _ = crate::text::write_u32(out, v);
    out.end_line();
}

/// Times the parts of each inversion with SysTick (a [`Probe`] of `invert_probed`): the
/// instructions of the encoder, the forward model and the correction, summed over the passes of
/// one inversion. Each reading is exact to ±40 instructions; the means over many lines are far
/// better. The probe's own readings add about 40 instructions to an inversion.
struct Timing<'c> {
    clock: &'c Clock,
    start: u32,
    parts: [u32; 3],
}

impl Probe for Timing<'_> {
    #[inline(always)]
    fn begin(&mut self, _: Part) {
        self.start = self.clock.now();
    }

    #[inline(always)]
    fn end(&mut self, part: Part) {
        let dt = self.clock.since(self.start);
        let i = match part {
            Part::Encoder => 0,
            Part::Forward => 1,
            Part::Correction => 2,
        };
        if let Some(p) = self.parts.get_mut(i) {
            *p += dt;
        }
    }
}
