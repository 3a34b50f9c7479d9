//! The exponential integral E1(x) = ∫₁^∞ e^(−xt)/t dt, x > 0.
//!
//! PROSPECT's leaf-layer transmissivity needs it (and its derivative −e^(−x)/x for training), once
//! per wavelength and leaf, so it is tuned for speed as well as accuracy: the convergent power
//! series for x ≤ 1 (a fixed polynomial, so four lanes evaluate it without branches), Taylor
//! patches of e^x·E1(x) on (1, 10] (coefficients computed at compile time from the differential
//! equation the function obeys), and the continued fraction above (Abramowitz & Stegun 5.1.11
//! and 5.1.22). The stated bound is checked against a table of 40-digit values in the tests.
//! [`e1_with_exp4`] evaluates four lanes with the same steps, bit for bit.

use super::lanes::{all, any, blend, mask, F64x4};
use super::Real;

/// Largest relative error of [`e1_f64`] against 40-digit test vectors on (1e-12, 80).
pub const E1_MAX_REL_ERROR: f64 = 2e-15;

/// Terms of the power series `Ein(x) = Σ_{k≥1} (−1)^(k+1) x^k / (k·k!)` summed for x ≤ 1: the
/// first term left out is below 3e-20 there, far below the sum (≥ 0.2 relative to E1).
const EIN_TERMS: usize = 20;

/// The series coefficients `(−1)^(k+1) / (k·k!)`, k = 1..=EIN_TERMS (index k − 1).
const EIN: [f64; EIN_TERMS] = {
    let mut t = [0.0; EIN_TERMS];
    let mut fact = 1.0; // k!
    let mut k = 1;
    while k <= EIN_TERMS {
        fact *= k as f64;
        let c = 1.0 / (k as f64 * fact);
        t[k - 1] = if k % 2 == 1 { c } else { -c };
        k += 1;
    }
    t
};

/// Euler–Mascheroni constant γ.
const EULER_GAMMA: f64 = 0.577_215_664_901_532_9;

/// `Ein(x)` by Horner's rule on the fixed series (x ≤ 1), for any [`Real`] (so scalar and lanes
/// take the same steps).
#[inline(always)]
fn ein<R: Real>(x: R) -> R {
    let mut s = R::c(EIN[EIN_TERMS - 1]);
    for &c in EIN[..EIN_TERMS - 1].iter().rev() {
        s = s * x + R::c(c);
    }
    s * x
}

/// Largest argument for which [`e1_f64`] sums the power series.
const E1_SERIES_MAX: f64 = 1.0;
/// Taylor patches of `h(x) = e^x·E1(x)`: width 0.25 on (1, 4], width 0.5 on (4, 10].
const E1_PATCHES: usize = 24;
/// Taylor terms per patch (|x − x0| / x0 ≤ 1/9 leaves < 1e-17).
const E1_TAYLOR_TERMS: usize = 18;
/// Above this the continued fraction converges in fewer than 20 steps.
const E1_TAYLOR_MAX: f64 = 10.0;

/// `e^x·E1(x)` by backward evaluation of the continued fraction
/// `1/(x + 1 − 1²/(x + 3 − 2²/(x + 5 − …)))` to `depth` levels (const, for the Taylor patches).
const fn h_cf(x: f64, depth: usize) -> f64 {
    let mut t = 0.0;
    let mut j = depth;
    while j >= 2 {
        let jm1 = (j - 1) as f64;
        t = -(jm1 * jm1) / (x + (2 * j - 1) as f64 + t);
        j -= 1;
    }
    1.0 / (x + 1.0 + t)
}

/// Patch centres.
const fn patch_centre(i: usize) -> f64 {
    if i < 12 {
        1.125 + 0.25 * i as f64
    } else {
        4.25 + 0.5 * (i - 12) as f64
    }
}

/// Taylor coefficients of `h(x) = e^x·E1(x)` around each patch centre x0. `h` obeys
/// `h' = h − 1/x`, so with `h = Σ aₙ (x − x0)ⁿ`:
/// `aₙ₊₁ = (aₙ − (−1)ⁿ / x0ⁿ⁺¹) / (n + 1)`, started from `a₀ = h(x0)` (continued fraction, 1500
/// levels). Computed at compile time; errors in aₙ are damped by the 1/(n+1) factors.
const E1_TAYLOR: [[f64; E1_TAYLOR_TERMS]; E1_PATCHES] = {
    let mut t = [[0.0; E1_TAYLOR_TERMS]; E1_PATCHES];
    let mut i = 0;
    while i < E1_PATCHES {
        let x0 = patch_centre(i);
        t[i][0] = h_cf(x0, 1500);
        let mut n = 0;
        let mut inv_pow = 1.0 / x0; // 1 / x0^(n+1)
        let mut sign = 1.0; // (−1)^n
        while n + 1 < E1_TAYLOR_TERMS {
            t[i][n + 1] = (t[i][n] - sign * inv_pow) / (n + 1) as f64;
            inv_pow /= x0;
            sign = -sign;
            n += 1;
        }
        i += 1;
    }
    t
};

/// The exponential integral E1(x), x > 0, in f64, tuned for PROSPECT (x from 1e-16 to ~100):
/// the power series `−γ − ln x − Σ (−x)^k / (k·k!)` for x ≤ 1; Taylor patches of `e^x·E1(x)`
/// (coefficients from the differential equation `h' = h − 1/x`, computed at compile time) for
/// 1 < x ≤ 10; the continued fraction `e^(−x) / (x + 1 − 1/(x + 3 − 4/(x + 5 − …)))` above. It
/// is within [`E1_MAX_REL_ERROR`] of E1 (a plain continued fraction converges slowly for
/// 1 < x < 4; the Taylor patches make that range as cheap as the rest).
pub fn e1_f64(x: f64) -> f64 {
    e1_with_exp(x, libm::exp(-x))
}

/// [`e1_f64`] given `ex = e^(−x)` (used for x > 1 only), for callers that need e^(−x) too.
#[inline]
pub fn e1_with_exp(x: f64, ex: f64) -> f64 {
    if x.is_nan() || x <= 0.0 {
        return if x == 0.0 { f64::INFINITY } else { f64::NAN };
    }
    if x <= E1_SERIES_MAX {
        // E1(x) = −γ − ln x + Ein(x).
        -EULER_GAMMA - libm::log(x) + ein(x)
    } else if x <= E1_TAYLOR_MAX {
        let i = if x <= 4.0 {
            libm::floor((x - 1.0) * 4.0) as usize
        } else {
            12 + libm::floor((x - 4.0) * 2.0) as usize
        }
        .min(E1_PATCHES - 1);
        let c = &E1_TAYLOR[i];
        let d = x - patch_centre(i);
        let mut h = 0.0;
        for &a in c.iter().rev() {
            h = h * d + a;
        }
        ex * h
    } else {
        // Forward recurrence of the continued fraction (one division); depth for 1e-16.
        let depth = 8 + libm::ceil(110.0 / x) as usize;
        let (mut a_prev, mut a) = (1.0f64, 0.0f64); // A_{-1}, A_0
        let (mut b_prev, mut b) = (0.0f64, 1.0f64); // B_{-1}, B_0
        for j in 1..=depth {
            let jm1 = (j - 1) as f64;
            let aj = if j == 1 { 1.0 } else { -jm1 * jm1 };
            let bj = x + (2 * j - 1) as f64;
            let a_next = bj * a + aj * a_prev;
            let b_next = bj * b + aj * b_prev;
            a_prev = a;
            a = a_next;
            b_prev = b;
            b = b_next;
        }
        ex * a / b
    }
}

/// [`e1_with_exp`] for four lanes: each lane takes the same steps as the scalar function (the
/// series with its own stopping term, the Taylor patch of its own argument, the continued
/// fraction to its own depth), so every lane equals the scalar result bit for bit. A regime is
/// evaluated only when some lane needs it.
pub(crate) fn e1_with_exp4(x: F64x4, ex: F64x4) -> F64x4 {
    if !all(mask(x, |v| v > 0.0)) {
        return x.zip(ex, e1_with_exp);
    }
    let series = mask(x, |v| v <= E1_SERIES_MAX);
    let taylor = mask(x, |v| v > E1_SERIES_MAX && v <= E1_TAYLOR_MAX);
    let cf = mask(x, |v| v > E1_TAYLOR_MAX);
    let mut out = F64x4::c(0.0);
    if any(series) {
        out = blend(series, e1_series4(series, x), out);
    }
    if any(taylor) {
        out = blend(taylor, ex * e1_taylor4(x), out);
    }
    if any(cf) {
        let (a, b) = e1_cf4(cf, x);
        out = blend(cf, ex * a / b, out);
    }
    out
}

/// The series branch of [`e1_with_exp`] for the lanes of `active` (x ≤ 1; other lanes are
/// evaluated at 1 and discarded by the caller).
fn e1_series4(active: [u64; 4], x: F64x4) -> F64x4 {
    let x = blend(active, x, F64x4::c(1.0));
    F64x4::c(-EULER_GAMMA) - super::lanes::ln4_of(x) + ein(x)
}

/// `e^x·E1(x)` on each lane's Taylor patch (1 < x ≤ 10; other lanes use a valid patch and are
/// discarded by the caller).
fn e1_taylor4(x: F64x4) -> F64x4 {
    let patch = |v: f64| -> usize {
        let v = v.clamp(1.0, E1_TAYLOR_MAX);
        if v <= 4.0 {
            libm::floor((v - 1.0) * 4.0) as usize
        } else {
            12 + libm::floor((v - 4.0) * 2.0) as usize
        }
        .min(E1_PATCHES - 1)
    };
    let i = [patch(x.0[0]), patch(x.0[1]), patch(x.0[2]), patch(x.0[3])];
    let d = x - F64x4([
        patch_centre(i[0]),
        patch_centre(i[1]),
        patch_centre(i[2]),
        patch_centre(i[3]),
    ]);
    let rows = [
        &E1_TAYLOR[i[0]],
        &E1_TAYLOR[i[1]],
        &E1_TAYLOR[i[2]],
        &E1_TAYLOR[i[3]],
    ];
    let mut h = F64x4::c(0.0);
    for n in (0..E1_TAYLOR_TERMS).rev() {
        h = h * d + F64x4([rows[0][n], rows[1][n], rows[2][n], rows[3][n]]);
    }
    h
}

/// The continued fraction's numerator and denominator `(A, B)`, `e^x·E1(x) = A/B`, for the lanes
/// of `active` (x > 10), each to its own depth.
fn e1_cf4(active: [u64; 4], x: F64x4) -> (F64x4, F64x4) {
    let c = F64x4::c;
    let x = blend(active, x, c(2.0 * E1_TAYLOR_MAX));
    let depth = x.0.map(|v| 8 + libm::ceil(110.0 / v) as usize);
    let (mut a_prev, mut a) = (c(1.0), c(0.0));
    let (mut b_prev, mut b) = (c(0.0), c(1.0));
    let max_depth = depth.iter().copied().max().unwrap_or(0);
    for j in 1..=max_depth {
        let jm1 = (j - 1) as f64;
        let aj = c(if j == 1 { 1.0 } else { -jm1 * jm1 });
        let bj = x + c((2 * j - 1) as f64);
        let a_next = bj * a + aj * a_prev;
        let b_next = bj * b + aj * b_prev;
        let go = depth.map(|dl| if j <= dl { u64::MAX } else { 0 });
        a_prev = blend(go, a, a_prev);
        a = blend(go, a_next, a);
        b_prev = blend(go, b, b_prev);
        b = blend(go, b_next, b);
    }
    (a, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_lanes_match_the_scalar_bit_for_bit() {
        // Lanes in one regime, lanes across regimes, and each branch boundary.
        let groups: [[f64; 4]; 8] = [
            [1e-12, 0.01, 0.5, 0.999],
            [1.0, 1.3, 2.6, 3.999],
            [4.0, 4.6, 6.1, 9.99],
            [10.0, 10.01, 15.0, 80.0],
            [0.2, 3.3, 12.0, 1e-6],
            [0.999, 1.0001, 9.9999, 10.0001],
            [2e-16, 0.7, 30.0, 5.5],
            [700.0, 0.05, 1.75, 8.0],
        ];
        for g in groups {
            let x = F64x4(g);
            let ex = x.map(|v| libm::exp(-v));
            let got = e1_with_exp4(x, ex);
            for (i, &xi) in g.iter().enumerate() {
                let want = e1_with_exp(xi, libm::exp(-xi));
                assert_eq!(got.0[i].to_bits(), want.to_bits(), "x {xi}");
            }
        }
        let bad = e1_with_exp4(F64x4([0.0, -1.0, 1.0, f64::NAN]), F64x4::c(1.0));
        assert!(bad.0[0].is_infinite() && bad.0[1].is_nan() && bad.0[3].is_nan());
    }

    /// E1 at 40 digits (mpmath), rounded to 20.
    #[allow(clippy::excessive_precision)]
    const E1_VECTORS: [(f64, f64); 22] = [
        (1e-12, 2.7053805451028015368e+1),
        (1e-06, 1.3238295893062491289e+1),
        (0.01, 4.0379295765381138112),
        (0.1, 1.8229239584193906159),
        (0.5, 5.5977359477616081175e-1),
        (0.999, 2.1975218202294454114e-1),
        (1.0, 2.1938393439552027368e-1),
        (1.0347383610327399, 2.0703584133945020168e-1),
        (1.3, 1.3545095784912912986e-1),
        (1.75, 6.9488684604638792638e-2),
        (2.0, 4.8900510708061119567e-2),
        (2.6, 2.1850221804082191073e-2),
        (3.3, 8.9390425420321405577e-3),
        (4.0, 3.7793524098489064789e-3),
        (4.6, 1.8410058172415038476e-3),
        (6.1, 3.2108702794965483304e-4),
        (8.0, 3.7665622843924901773e-5),
        (9.99, 4.2026194847832813939e-6),
        (10.01, 4.111817778982802173e-6),
        (15.0, 1.9186278921478669771e-8),
        (30.0, 3.0215520106888125448e-15),
        (80.0, 2.2285432586884729112e-37),
    ];

    #[test]
    fn matches_40_digit_vectors() {
        for (x, want) in E1_VECTORS {
            let rel = ((e1_f64(x) - want) / want).abs();
            assert!(rel < E1_MAX_REL_ERROR, "x {x}: rel {rel:e}");
        }
        assert!(e1_f64(0.0).is_infinite() && e1_f64(-1.0).is_nan() && e1_f64(f64::NAN).is_nan());
    }

    #[test]
    fn continuous_across_branches() {
        for x in [1.0, 4.0, 10.0] {
            let (a, b) = (e1_f64(x - 1e-12), e1_f64(x + 1e-12));
            assert!(((a - b) / a).abs() < 1e-10, "x {x}");
        }
    }

    #[test]
    fn edge_cases() {
        assert!(e1_f64(-1.0).is_nan());
        assert!(e1_f64(f64::NAN).is_nan());
        assert_eq!(e1_f64(0.0), f64::INFINITY);
        assert!(e1_f64(800.0) == 0.0);
    }
}
