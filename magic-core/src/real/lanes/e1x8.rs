//! The exponential integral E1 in `f32` ([`crate::real::e1_with_exp_f32`]) for eight lanes.
//!
//! Each lane takes the scalar function's steps (the series, the Taylor patch of its own argument,
//! above 10 the `f64` function), so every lane equals the scalar result bit for bit. A regime is
//! evaluated only when some lane needs it.

use super::e1x4::e1_with_exp4;
use super::libm32::logf8;
use super::libm64::exp4;
use super::vector::{F32x8, F64x4};
use crate::real::e1::{
    e1_series, e1_with_exp_f32, ein12, patch_centre, taylor_h, E1_PATCHES, E1_SERIES_MAX,
    E1_TAYLOR, E1_TAYLOR_MAX, E1_TAYLOR_TERMS_F32,
};
use crate::real::{Cmp, Real};

/// E1 of eight lanes given `ex` = e^(−x) (used for 1 < x ≤ 10), as [`e1_with_exp_f32`] lane by
/// lane.
#[inline(always)]
pub(crate) fn e1_with_exp8(x: F32x8, ex: F32x8) -> F32x8 {
    // Most of PROSPECT's plate absorptions are at most 1 (the series for every lane).
    if (x.mask(Cmp::Gt(0.0)) & x.mask(Cmp::Le(E1_SERIES_MAX))).all() {
        return e1_series(logf8(x), ein12(x));
    }
    e1_regimes8(x, ex)
}

/// [`e1_with_exp8`] for lanes in several regimes (or outside the domain).
#[inline(never)]
fn e1_regimes8(x: F32x8, ex: F32x8) -> F32x8 {
    if !x.all(Cmp::Gt(0.0)) {
        return x.zip(ex, e1_with_exp_f32);
    }
    let series = x.mask(Cmp::Le(E1_SERIES_MAX));
    let above = x.mask(Cmp::Gt(E1_TAYLOR_MAX));
    let taylor = !(series | above);
    let mut out = F32x8::c(0.0);
    if F32x8::mask_any(series) {
        let xs = F32x8::blend(series, x, F32x8::c(1.0));
        out = F32x8::blend(series, e1_series(logf8(xs), ein12(xs)), out);
    }
    if F32x8::mask_any(taylor) {
        out = F32x8::blend(taylor, ex * e1_taylor8(x), out);
    }
    if F32x8::mask_any(above) {
        // Through the f64 function, as the scalar does.
        let a = x.to_array();
        let half = |o: usize| {
            let h = F64x4::new([
                a[o] as f64,
                a[o + 1] as f64,
                a[o + 2] as f64,
                a[o + 3] as f64,
            ]);
            e1_with_exp4(h, exp4(-h)).to_array()
        };
        let (lo, hi) = (half(0), half(4));
        let e = F32x8::new([
            lo[0] as f32,
            lo[1] as f32,
            lo[2] as f32,
            lo[3] as f32,
            hi[0] as f32,
            hi[1] as f32,
            hi[2] as f32,
            hi[3] as f32,
        ]);
        out = F32x8::blend(above, e, out);
    }
    out
}

/// `e^x·E1(x)` on each lane's Taylor patch (1 < x ≤ 10; other lanes use a valid patch and are
/// discarded by the caller).
#[inline]
fn e1_taylor8(x: F32x8) -> F32x8 {
    let c = |v: f32| F32x8::splat(v);
    // The patch index of every lane, as `patch_index` computes it (exact in f32 here).
    let xc = x.max(c(E1_SERIES_MAX as f32)).min(c(E1_TAYLOR_MAX as f32));
    let near = F32x8(((xc - c(1.0)) * c(4.0)).0.floor());
    let far = c(12.0) + F32x8(((xc - c(4.0)) * c(2.0)).0.floor());
    let i = F32x8::blend(xc.mask(Cmp::Le(4.0)), near, far).min(c((E1_PATCHES - 1) as f32));
    let idx = i.to_array().map(|v| v as usize);
    if idx.iter().all(|&j| j == idx[0]) {
        // One patch for all lanes (neighbouring wavelengths): each coefficient read once.
        let p = idx[0];
        return taylor_h(
            &E1_TAYLOR[p],
            E1_TAYLOR_TERMS_F32,
            x - c(patch_centre(p) as f32),
        );
    }
    let d = x - F32x8::new(idx.map(|j| patch_centre(j) as f32));
    let mut h = F32x8::c(0.0);
    for n in (0..E1_TAYLOR_TERMS_F32).rev() {
        h = h * d + F32x8::new(idx.map(|j| E1_TAYLOR[j][n] as f32));
    }
    h
}

#[cfg(test)]
mod tests {
    use super::super::tests::{check_lanes, spread};
    use super::*;

    #[test]
    fn eight_lanes_match_the_scalar_bit_for_bit() {
        let e1 = |x: F32x8| e1_with_exp8(x, x.map(|v| libm::expf(-v)));
        let one = |x: f32| e1_with_exp_f32(x, libm::expf(-x));
        let special = [
            1e-12,
            0.999,
            1.0,
            1.0001,
            3.999,
            4.0,
            9.999,
            10.0,
            10.001,
            30.0,
            700.0,
            0.0,
            -1.0,
            f64::NAN,
        ];
        let xs = spread(40_000, 0.0, 2.0)
            .chain(spread(40_000, 0.0, 12.0))
            .chain(spread(4_000, 0.0, 1e-6))
            .chain(special);
        check_lanes(e1, one, xs);
        // Lanes on one patch, lanes across patches and regimes.
        check_lanes(
            e1,
            one,
            [2.01, 2.05, 2.1, 2.2, 2.03, 2.04, 2.06, 2.07].into_iter(),
        );
        check_lanes(
            e1,
            one,
            [0.2, 3.3, 12.0, 1e-6, 5.5, 0.7, 30.0, 9.0].into_iter(),
        );
    }
}
