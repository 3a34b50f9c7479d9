//! The exponential integral E1 ([`crate::real::e1_with_exp`]) for four `f64` lanes.
//!
//! Each lane takes the same steps as the scalar function (the series with the same terms, the
//! Taylor patch of its own argument, the continued fraction to its own depth), so every lane equals
//! the scalar result bit for bit. A regime is evaluated only when some lane needs it; neighbouring
//! wavelengths usually share a Taylor patch, whose coefficients are then read once for all lanes.

use super::libm64::ln4;
use super::vector::F64x4;
use crate::real::e1::{
    cf_depth, e1_with_exp, ein, patch_centre, patch_index, E1_PATCHES, E1_SERIES_MAX, E1_TAYLOR,
    E1_TAYLOR_MAX, E1_TAYLOR_TERMS, EULER_GAMMA,
};
use crate::real::{Cmp, Real};

/// E1 of four lanes given `ex` = e^(−x) (used for x > 1), as [`e1_with_exp`] lane by lane.
#[inline(always)]
pub(crate) fn e1_with_exp4(x: F64x4, ex: F64x4) -> F64x4 {
    // Most of PROSPECT's plate absorptions are at most 1 (the series for every lane).
    if (x.mask(Cmp::Gt(0.0)) & x.mask(Cmp::Le(E1_SERIES_MAX))).all() {
        return F64x4::c(-EULER_GAMMA) - ln4(x) + ein(x);
    }
    e1_regimes4(x, ex)
}

/// [`e1_with_exp4`] for lanes in several regimes (or outside the domain).
#[inline(never)]
fn e1_regimes4(x: F64x4, ex: F64x4) -> F64x4 {
    if !x.all(Cmp::Gt(0.0)) {
        return x.zip(ex, e1_with_exp);
    }
    let series = x.mask(Cmp::Le(E1_SERIES_MAX));
    let cf = x.mask(Cmp::Gt(E1_TAYLOR_MAX));
    let taylor = !(series | cf);
    let mut out = F64x4::c(0.0);
    if F64x4::mask_any(series) {
        out = F64x4::blend(series, e1_series4(series, x), out);
    }
    if F64x4::mask_any(taylor) {
        out = F64x4::blend(taylor, ex * e1_taylor4(x), out);
    }
    if F64x4::mask_any(cf) {
        let (a, b) = e1_cf4(cf, x);
        out = F64x4::blend(cf, ex * a / b, out);
    }
    out
}

/// The series branch for the lanes of `active` (x ≤ 1; other lanes are evaluated at 1 and
/// discarded by the caller).
#[inline]
fn e1_series4(active: <F64x4 as Real>::Mask, x: F64x4) -> F64x4 {
    let x = F64x4::blend(active, x, F64x4::c(1.0));
    F64x4::c(-EULER_GAMMA) - ln4(x) + ein(x)
}

/// `e^x·E1(x)` on each lane's Taylor patch (1 < x ≤ 10; other lanes use a valid patch and are
/// discarded by the caller).
#[inline]
fn e1_taylor4(x: F64x4) -> F64x4 {
    let c = F64x4::c;
    // The patch index of every lane, as `patch_index` computes it, in floating point.
    let xc = x.max(c(E1_SERIES_MAX)).min(c(E1_TAYLOR_MAX));
    let near = F64x4(((xc - c(1.0)) * c(4.0)).0.floor());
    let far = c(12.0) + F64x4(((xc - c(4.0)) * c(2.0)).0.floor());
    let i = F64x4::blend(xc.mask(Cmp::Le(4.0)), near, far).min(c((E1_PATCHES - 1) as f64));
    let first = i.to_array()[0];
    let mut h = F64x4::c(0.0);
    if i.all(Cmp::Eq(first)) {
        // One patch for all lanes (neighbouring wavelengths): each coefficient read once.
        let p = first as usize;
        let d = x - c(patch_centre(p));
        for &a in E1_TAYLOR[p].iter().rev() {
            h = h * d + c(a);
        }
    } else {
        let i = x.to_array().map(patch_index);
        let d = x - F64x4::new(i.map(patch_centre));
        for n in (0..E1_TAYLOR_TERMS).rev() {
            h = h * d + F64x4::new(i.map(|j| E1_TAYLOR[j][n]));
        }
    }
    h
}

/// The continued fraction's numerator and denominator `(A, B)`, `e^x·E1(x) = A/B`, for the lanes
/// of `active` (x > 10), each to its own depth.
#[inline]
fn e1_cf4(active: <F64x4 as Real>::Mask, x: F64x4) -> (F64x4, F64x4) {
    let c = F64x4::c;
    let x = F64x4::blend(active, x, c(2.0 * E1_TAYLOR_MAX));
    let depth = x.to_array().map(cf_depth);
    let (mut a_prev, mut a) = (c(1.0), c(0.0));
    let (mut b_prev, mut b) = (c(0.0), c(1.0));
    let max_depth = depth.iter().copied().max().unwrap_or(0);
    for j in 1..=max_depth {
        let jm1 = (j - 1) as f64;
        let aj = c(if j == 1 { 1.0 } else { -jm1 * jm1 });
        let bj = x + c((2 * j - 1) as f64);
        let a_next = bj * a + aj * a_prev;
        let b_next = bj * b + aj * b_prev;
        let go = F64x4::new(depth.map(|dl| dl as f64)).mask(Cmp::Ge(j as f64));
        a_prev = F64x4::blend(go, a, a_prev);
        a = F64x4::blend(go, a_next, a);
        b_prev = F64x4::blend(go, b, b_prev);
        b = F64x4::blend(go, b_next, b);
    }
    (a, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_lanes_match_the_scalar_bit_for_bit() {
        // Lanes in one regime, lanes across regimes, one patch for all lanes, and each branch
        // boundary.
        let groups: [[f64; 4]; 9] = [
            [1e-12, 0.01, 0.5, 0.999],
            [1.0, 1.3, 2.6, 3.999],
            [4.0, 4.6, 6.1, 9.99],
            [10.0, 10.01, 15.0, 80.0],
            [0.2, 3.3, 12.0, 1e-6],
            [0.999, 1.0001, 9.9999, 10.0001],
            [2e-16, 0.7, 30.0, 5.5],
            [700.0, 0.05, 1.75, 8.0],
            [2.01, 2.05, 2.1, 2.2],
        ];
        for g in groups {
            let x = F64x4::new(g);
            let ex = x.map(|v| libm::exp(-v));
            let got = e1_with_exp4(x, ex);
            for (i, &xi) in g.iter().enumerate() {
                let want = e1_with_exp(xi, libm::exp(-xi));
                assert_eq!(got.to_array()[i].to_bits(), want.to_bits(), "x {xi}");
            }
        }
        let bad = e1_with_exp4(F64x4::new([0.0, -1.0, 1.0, f64::NAN]), F64x4::c(1.0)).to_array();
        assert!(bad[0].is_infinite() && bad[1].is_nan() && bad[3].is_nan());
    }
}
