//! The exponential integral E1(x) = ∫₁^∞ e^(−xt)/t dt, x > 0.
//!
//! PROSPECT's leaf-layer transmissivity needs it (and its derivative −e^(−x)/x for training), once
//! per wavelength and leaf, so it is tuned for speed as well as accuracy: the convergent power
//! series for x ≤ 1 (a fixed polynomial, so four lanes evaluate it without branches), Taylor
//! patches of e^x·E1(x) on (1, 10] (coefficients computed at compile time from the differential
//! equation the function obeys), and the continued fraction above (Abramowitz & Stegun 5.1.11
//! and 5.1.22). The stated bound is checked against a table of 40-digit values in the tests.
//! Lanes evaluate it with the same steps and these tables (`lanes::e1x4`), bit for bit.
//!
//! [`e1_f32`] is the same function in `f32` arithmetic for the `f32` path (the board, `f32`
//! lanes): the series to fewer terms, the Taylor patches to fewer terms, the continued fraction
//! (never met by PROSPECT's absorptions, and overflowing `f32`) through [`e1_f64`].

use super::Real;

/// Largest relative error of [`e1_f64`] against 40-digit test vectors on (1e-12, 80).
pub const E1_MAX_REL_ERROR: f64 = 2e-15;

/// Terms of the power series `Ein(x) = Σ_{k≥1} (−1)^(k+1) x^k / (k·k!)` summed for x ≤ 1: the
/// first term left out is below 3e-20 there, far below the sum (≥ 0.2 relative to E1).
const EIN_TERMS: usize = 20;
// `ein` sums the terms as five cubics.
const _: () = assert!(EIN_TERMS == 20);

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
pub(in crate::real) const EULER_GAMMA: f64 = 0.577_215_664_901_532_9;

/// `Ein(x)` on the fixed series (x ≤ 1), for any [`Real`] (so scalar and lanes take the same
/// steps), by Estrin's scheme: `Σ cₖ xᵏ = x·(p₀(x) + x⁴·p₁(x) + x⁸·p₂(x) + …)` with the cubics
/// `pⱼ(x) = c₄ⱼ₊₁ + c₄ⱼ₊₂ x + x²(c₄ⱼ₊₃ + c₄ⱼ₊₄ x)`: the same number of operations as Horner's rule
/// but a chain of 12 dependent operations instead of 40 (it lies on the path of every
/// wavelength's computation).
#[inline(always)]
pub(in crate::real) fn ein<R: Real>(x: R) -> R {
    let c = |k: usize| R::c(EIN[k]);
    let x2 = x * x;
    let x4 = x2 * x2;
    let cubic = |j: usize| (c(4 * j) + c(4 * j + 1) * x) + x2 * (c(4 * j + 2) + c(4 * j + 3) * x);
    let (p0, p1, p2, p3, p4) = (cubic(0), cubic(1), cubic(2), cubic(3), cubic(4));
    let x8 = x4 * x4;
    // p₀ + x⁴p₁ + x⁸(p₂ + x⁴p₃) + x¹⁶p₄
    x * ((p0 + x4 * p1) + x8 * ((p2 + x4 * p3) + x8 * p4))
}

/// `Ein(x)` to 12 terms (x ≤ 1, enough for `f32`: the first term left out is below 2.3e-9), by
/// Estrin's scheme as [`ein`].
#[inline(always)]
pub(in crate::real) fn ein12<R: Real>(x: R) -> R {
    let c = |k: usize| R::c(EIN[k]);
    let x2 = x * x;
    let x4 = x2 * x2;
    let cubic = |j: usize| (c(4 * j) + c(4 * j + 1) * x) + x2 * (c(4 * j + 2) + c(4 * j + 3) * x);
    x * (cubic(0) + x4 * (cubic(1) + x4 * cubic(2)))
}

/// E1 on its series, given `ln x`: `−γ − ln x + Ein(x)` (x ≤ 1), with the terms `ein` sums.
#[inline(always)]
pub(in crate::real) fn e1_series<R: Real>(ln_x: R, ein: R) -> R {
    R::c(-EULER_GAMMA) - ln_x + ein
}

/// Taylor terms per patch in `f32` (|x − x0| / x0 ≤ 1/9 leaves < 3e-9).
pub(in crate::real) const E1_TAYLOR_TERMS_F32: usize = 9;

/// `h(x0 + d) = e^(x0 + d)·E1(x0 + d)` on the patch `row` of [`E1_TAYLOR`] to `terms` terms, by
/// Horner's rule (coefficients rounded to `R`).
#[inline(always)]
pub(in crate::real) fn taylor_h<R: Real>(row: &[f64; E1_TAYLOR_TERMS], terms: usize, d: R) -> R {
    let mut h = R::zero();
    for &a in row[..terms].iter().rev() {
        h = h * d + R::c(a);
    }
    h
}

/// Largest argument for which [`e1_f64`] sums the power series.
pub(in crate::real) const E1_SERIES_MAX: f64 = 1.0;
/// Taylor patches of `h(x) = e^x·E1(x)`: width 0.25 on (1, 4], width 0.5 on (4, 10].
pub(in crate::real) const E1_PATCHES: usize = 24;
/// Taylor terms per patch (|x − x0| / x0 ≤ 1/9 leaves < 1e-17).
pub(in crate::real) const E1_TAYLOR_TERMS: usize = 18;
/// Above this the continued fraction converges in fewer than 20 steps.
pub(in crate::real) const E1_TAYLOR_MAX: f64 = 10.0;

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
pub(in crate::real) const fn patch_centre(i: usize) -> f64 {
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
pub(in crate::real) const E1_TAYLOR: [[f64; E1_TAYLOR_TERMS]; E1_PATCHES] = {
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
        e1_series(libm::log(x), ein(x))
    } else if x <= E1_TAYLOR_MAX {
        let i = patch_index(x);
        ex * taylor_h(&E1_TAYLOR[i], E1_TAYLOR_TERMS, x - patch_centre(i))
    } else {
        // Forward recurrence of the continued fraction (one division); depth for 1e-16.
        let depth = cf_depth(x);
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

/// Largest relative error of [`e1_f32`] against E1 on (1e-8, 80): measured 5.8e-7 (at x ≈ 0.98,
/// 2·10⁶ log-spaced points; E1 rounded to `f32` alone is within 6e-8: the loss is the
/// cancellation in `−γ − ln x + Ein(x)` near 1), bound with a margin of 40 %.
pub const E1_F32_MAX_REL_ERROR: f64 = 8e-7;

/// The exponential integral E1(x), x > 0, in `f32` arithmetic (within [`E1_F32_MAX_REL_ERROR`]):
/// the steps of [`e1_f64`] with 12 series terms and 9 Taylor terms; above 10 through [`e1_f64`].
pub fn e1_f32(x: f32) -> f32 {
    e1_with_exp_f32(x, libm::expf(-x))
}

/// [`e1_f32`] given `ex = e^(−x)` (used for 1 < x ≤ 10 only).
#[inline]
pub fn e1_with_exp_f32(x: f32, ex: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        return if x == 0.0 { f32::INFINITY } else { f32::NAN };
    }
    if x <= E1_SERIES_MAX as f32 {
        e1_series(libm::logf(x), ein12(x))
    } else if x <= E1_TAYLOR_MAX as f32 {
        let i = patch_index(x as f64);
        ex * taylor_h(
            &E1_TAYLOR[i],
            E1_TAYLOR_TERMS_F32,
            x - patch_centre(i) as f32,
        )
    } else {
        e1_f64(x as f64) as f32
    }
}

/// The Taylor patch of `x` in (1, 10] (arguments outside are clamped into that range).
#[inline(always)]
pub(in crate::real) fn patch_index(x: f64) -> usize {
    let x = x.clamp(E1_SERIES_MAX, E1_TAYLOR_MAX);
    if x <= 4.0 {
        libm::floor((x - 1.0) * 4.0) as usize
    } else {
        12 + libm::floor((x - 4.0) * 2.0) as usize
    }
    .min(E1_PATCHES - 1)
}

/// Levels of the continued fraction for 1e-16 at `x` > 10.
#[inline(always)]
pub(in crate::real) fn cf_depth(x: f64) -> usize {
    8 + libm::ceil(110.0 / x) as usize
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn f32_matches_40_digit_vectors() {
        for (x, want) in E1_VECTORS {
            let x32 = x as f32;
            // The vector's argument rounded to f32: E1 there, to first order.
            let want = want * (1.0 - (x32 as f64 - x) * libm::exp(-x) / x / want);
            let rel = ((e1_f32(x32) as f64 - want) / want).abs();
            assert!(rel < E1_F32_MAX_REL_ERROR, "x {x}: rel {rel:e}");
        }
        // Densely against the f64 function (itself within 2e-15).
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            let x = 1e-8 * libm::pow(80.0 / 1e-8, i as f64 / 199_999.0);
            let x32 = x as f32;
            let want = e1_f64(x32 as f64);
            worst = worst.max(((e1_f32(x32) as f64 - want) / want).abs());
        }
        assert!(worst < E1_F32_MAX_REL_ERROR, "worst {worst:e}");
        assert!(e1_f32(0.0).is_infinite() && e1_f32(-1.0).is_nan() && e1_f32(f32::NAN).is_nan());
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
