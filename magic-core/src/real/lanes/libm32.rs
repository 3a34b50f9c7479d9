//! `libm`'s `expf` and `logf` (FreeBSD's `e_expf.c`, `e_logf.c`) for eight `f32` lanes at once,
//! step by step, so that every lane equals the scalar function bit for bit: their branches become
//! blends; lanes outside the ranges the steps cover send the batch through `libm` lane by lane.

use super::vector::F32x8;
use crate::real::{Cmp, Real};
use wide::{f32x8, i32x8, u32x8};

/// `2^k` for integer-valued lanes `k` in [−126, 127], built from exponent bits (what `scalbnf`
/// multiplies by in that range).
#[inline(always)]
fn pow2(k: F32x8) -> F32x8 {
    // The low bits of 2^23 + (k + 127) hold k + 127; shifted into the exponent field.
    let b = (k + F32x8::c(127.0 + 8_388_608.0)).bits();
    F32x8::from_bits(b << 23)
}

/// `e^x` for eight lanes: `libm::expf` step by step, for |x| < 87.34 (its thresholds on the bits
/// of |x|); lanes outside that range (or NaN) send the batch through `libm::expf`.
#[inline]
pub(crate) fn expf8(x: F32x8) -> F32x8 {
    // Its constants by their bits, as e_expf.c gives them.
    const LN2_HI: f32 = f32::from_bits(0x3f31_7200);
    const LN2_LO: f32 = f32::from_bits(0x35bf_be8e);
    const INV_LN2: f32 = f32::from_bits(0x3fb8_aa3b);
    const P1: f32 = f32::from_bits(0x3e2a_aa8f);
    const P2: f32 = f32::from_bits(0xbb35_5215);
    let c = |v: f32| F32x8::splat(v);
    let sign = u32x8::splat(1 << 31);
    let ax = F32x8::from_bits(x.bits() & !sign);
    // |x| compared through its bits as e_expf.c does (the same order as the values, NaN aside).
    let above = |bits: u32| ax.0.simd_gt(f32x8::splat(f32::from_bits(bits)));
    if !ax
        .0
        .simd_lt(f32x8::splat(f32::from_bits(0x42ae_ac50)))
        .all()
    {
        return x.map(libm::expf);
    }
    // Argument reduction x = k·ln 2 + r: k = ±1 just above 0.5·ln 2, rounded x/ln 2 beyond
    // 1.5·ln 2, 0 below 0.5·ln 2 (where hi = x, lo = 0 then give the same steps).
    let half = F32x8::from_bits(u32x8::splat(0.5f32.to_bits()) | (x.bits() & sign));
    let k_far = F32x8((c(INV_LN2) * x + half).0.trunc());
    let k = F32x8(above(0x3f85_1592).select(
        k_far.0,
        above(0x3eb1_7218).select((half + half).0, f32x8::ZERO),
    ));
    let hi = x - k * c(LN2_HI);
    let lo = k * c(LN2_LO);
    let r = hi - lo;
    let xx = r * r;
    let p = r - xx * (c(P1) + xx * c(P2));
    let y = c(1.0) + (r * p / (c(2.0) - p) - lo + hi);
    // |x| ≤ 2^-14: 1 + x.
    F32x8(above(0x3900_0000).select((y * pow2(k)).0, (c(1.0) + x).0))
}

/// `ln x` for eight lanes: `libm::logf` step by step, for positive normal finite `x`; other lanes
/// send the batch through `libm::logf`.
#[inline]
pub(crate) fn logf8(x: F32x8) -> F32x8 {
    // Its constants by their bits, as e_logf.c gives them.
    const LN2_HI: f32 = f32::from_bits(0x3f31_7180);
    const LN2_LO: f32 = f32::from_bits(0x3717_f7d1);
    const LG1: f32 = f32::from_bits(0x3f2a_aaaa);
    const LG2: f32 = f32::from_bits(0x3ecc_ce13);
    const LG3: f32 = f32::from_bits(0x3e91_e9ee);
    const LG4: f32 = f32::from_bits(0x3e78_9e26);
    let c = |v: f32| F32x8::splat(v);
    if !(x.all(Cmp::Ge(f32::MIN_POSITIVE as f64)) && x.all(Cmp::Lt(f64::INFINITY))) {
        return x.map(libm::logf);
    }
    // x = m·2^k with m in [sqrt(2)/2, sqrt(2)]: the offset moves the mantissa boundary to
    // sqrt(2)/2, the exponent field then holds k + 127.
    let ui = x.bits() + u32x8::splat(0x3f80_0000 - 0x3f35_04f3);
    let k: i32x8 = bytemuck::cast(ui >> 23);
    let dk = F32x8(f32x8::from_i32x8(k - i32x8::splat(0x7f)));
    let m = F32x8::from_bits((ui & u32x8::splat(0x007f_ffff)) + u32x8::splat(0x3f35_04f3));
    let f = m - c(1.0);
    let s = f / (c(2.0) + f);
    let z = s * s;
    let w = z * z;
    let t1 = w * (c(LG2) + w * c(LG4));
    let t2 = z * (c(LG1) + w * c(LG3));
    let r = t2 + t1;
    let hfsq = c(0.5) * f * f;
    s * (hfsq + r) + dk * c(LN2_LO) - hfsq + f + dk * c(LN2_HI)
}

#[cfg(test)]
mod tests {
    use super::super::tests::{check_lanes, spread};
    use super::*;

    #[test]
    fn expf_is_libm_bit_for_bit() {
        let special = [
            0.0,
            -0.0,
            1e-30,
            6.1e-5,
            -6.1e-5,
            0.3465736,
            0.34657362,
            1.0397208,
            -1.0397208,
            87.33,
            -87.33,
            -87.34,
            88.8,
            -104.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let xs = spread(40_000, -90.0, 90.0)
            .chain(spread(40_000, -2.0, 2.0))
            .chain(spread(8_000, -1e-3, 1e-3))
            .chain(special);
        check_lanes(expf8, libm::expf, xs);
        check_lanes(
            expf8,
            libm::expf,
            [0.5, f64::NAN, -3.0, 100.0, 1.0, 2.0, 3.0, 4.0].into_iter(),
        );
    }

    #[test]
    fn logf_is_libm_bit_for_bit() {
        let special = [
            1.0,
            0.0,
            -1.0,
            1.1754944e-38,
            1e-45,
            3.4e38,
            f64::INFINITY,
            f64::NAN,
            core::f64::consts::SQRT_2,
            core::f64::consts::FRAC_1_SQRT_2,
        ];
        let xs = spread(40_000, 0.0, 10.0)
            .chain(spread(40_000, 0.5, 2.0))
            .chain(spread(8_000, 0.0, 1e-30))
            .chain(spread(8_000, 0.0, 1e30))
            .chain(special);
        check_lanes(logf8, libm::logf, xs);
    }
}
