//! The variables' standard deviations appended to a result line (feature `sd`): the host's
//! [`magic_core::uncertainty::standard_deviations`] (the exact Jacobian of the forward model at
//! the solution and a Cholesky solve, in f64: software floating point on the M4F) on the board's
//! inversion, its f32 variables and reconstruction widened to f64; written as `magic invert
//! --sd` writes them, `NaN` where they cannot be computed.

use crate::text::write_fixed6;
use core::fmt::Write;
use core::sync::atomic::{AtomicBool, Ordering};
use magic_core::model_file::{Model, MAX_OBS, MAX_PARAMS};
use magic_core::uncertainty::{standard_deviations_for, Precision, SdWorkspace};
use magic_core::{Flags, Inversion};

/// The working memory: the Jacobian's (about 13 KiB) and the widened inversion.
pub struct SdState {
    sw: SdWorkspace,
    wide: Inversion<f64>,
}

/// The state, initialised at link time: built at run time (as `cortex_m::singleton!` does) it
/// would pass through the stack, and it is twice the stack budget.
static mut STATE: SdState = SdState {
    sw: SdWorkspace::with_precision(Precision::F64),
    wide: Inversion {
        n_params: 0,
        params: [0.0; MAX_PARAMS],
        unit: [0.0; MAX_PARAMS],
        n_obs: 0,
        physics: [0.0; MAX_OBS],
        recon: [0.0; MAX_OBS],
        residual_rms: 0.0,
        residual_rms_std: 0.0,
        flags: Flags(0),
        used: 0,
    },
};

/// Whether [`state`] has handed out [`STATE`].
static TAKEN: AtomicBool = AtomicBool::new(false);

/// The working memory, once (`None` after the first call).
pub fn state() -> Option<&'static mut SdState> {
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    // SAFETY: `TAKEN` lets exactly one caller through, so this is the only reference to STATE.
    #[allow(unsafe_code)]
    Some(unsafe { &mut *core::ptr::addr_of_mut!(STATE) })
}

/// Writes `,<sd>` for each of the model's variables: those of `inv`, the board's inversion of
/// `obs` on day `day` (NaN: unknown).
#[inline(never)]
pub fn write_sds<W: Write>(
    out: &mut W,
    model: &Model<'_>,
    obs: &[f32],
    day: f64,
    inv: &Inversion<f32>,
    s: &mut SdState,
) {
    let w = &mut s.wide;
    w.n_params = inv.n_params;
    w.n_obs = inv.n_obs;
    for (a, b) in w.params.iter_mut().zip(&inv.params) {
        *a = *b as f64;
    }
    for (a, b) in w.recon.iter_mut().zip(&inv.recon) {
        *a = *b as f64;
    }
    for (a, b) in w.physics.iter_mut().zip(&inv.physics) {
        *a = *b as f64;
    }
    w.unit = inv.unit;
    w.residual_rms = inv.residual_rms;
    w.residual_rms_std = inv.residual_rms_std;
    w.flags = inv.flags;
    w.used = inv.used;
    let u = standard_deviations_for::<crate::Linked>(model, obs, w, day, &mut s.sw).ok();
    for k in 0..model.n_params() {
        let _ = out.write_char(',');
        let v = u
            .as_ref()
            .and_then(|u| u.sd.get(k))
            .map_or(f32::NAN, |v| *v as f32);
        let _ = write_fixed6(out, v);
    }
}
