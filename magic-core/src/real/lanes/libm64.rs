//! `libm`'s `exp` and `log` (FreeBSD's `e_exp.c`, `e_log.c`) for four `f64` lanes at once, step
//! by step, so that every lane equals the scalar function bit for bit: their branches become
//! blends; lanes outside the ranges the steps cover send the batch through `libm` lane by lane.

use super::vector::F64x4;
use crate::real::{Cmp, Real};
use wide::{f64x4, u64x4};

/// Lanes rounded toward zero (as `as i32` does in `e_exp.c`; exact for these magnitudes).
#[inline(always)]
fn trunc(t: F64x4) -> F64x4 {
    F64x4(t.0.trunc())
}

/// `2^k` for integer-valued lanes `k` in [−1022, 1023], built from exponent bits.
#[inline(always)]
fn pow2(k: F64x4) -> F64x4 {
    // The low bits of 2^52 + (k + 1023) hold k + 1023; shifted into the exponent field.
    let b = (k + F64x4::c(1023.0 + 4_503_599_627_370_496.0)).bits();
    F64x4::from_bits(b << 52)
}

/// `e^x` for four lanes: `libm::exp` step by step, with its branches as blends, for
/// |x| < 708.39; lanes outside that range (or NaN) send the batch through `libm::exp`.
#[inline]
pub(crate) fn exp4(x: F64x4) -> F64x4 {
    // Boundaries of e_exp.c, as |x| thresholds (its tests on the high word of |x|); its constants
    // by their bits, as e_exp.c gives them.
    const SPECIAL: f64 = f64::from_bits(0x4086_232b_0000_0000); // ≈ 708.39
    const REDUCE: f64 = f64::from_bits(0x3fd6_2e43_0000_0000); // > 0.5·ln 2
    const FAR: f64 = f64::from_bits(0x3ff0_a2b2_0000_0000); // ≥ 1.5·ln 2
    const TINY: f64 = f64::from_bits(0x3e30_0001_0000_0000); // > 2^-28
    const LN2HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    const INVLN2: f64 = f64::from_bits(0x3ff7_1547_652b_82fe);
    const P1: f64 = f64::from_bits(0x3fc5_5555_5555_553e);
    const P2: f64 = f64::from_bits(0xbf66_c16c_16be_bd93);
    const P3: f64 = f64::from_bits(0x3f11_566a_af25_de2c);
    const P4: f64 = f64::from_bits(0xbebb_bd41_c5d2_6bf1);
    const P5: f64 = f64::from_bits(0x3e66_3769_72be_a4d0);
    let c = F64x4::c;
    let sign = u64x4::splat(1 << 63);
    let ax = F64x4::from_bits(x.bits() & !sign);
    if !ax.all(Cmp::Lt(SPECIAL)) {
        return x.map(libm::exp);
    }
    // Argument reduction x = k·ln 2 + r: k = ±1 just above 0.5·ln 2, rounded x/ln 2 beyond
    // 1.5·ln 2, 0 below 0.5·ln 2.
    // ±0.5 with the sign of x.
    let half = F64x4::from_bits(u64x4::splat(0.5f64.to_bits()) | (x.bits() & sign));
    let k_far = trunc(c(INVLN2) * x + half);
    let k = F64x4::blend(
        ax.mask(Cmp::Ge(FAR)),
        k_far,
        F64x4::blend(ax.mask(Cmp::Ge(REDUCE)), half + half, c(0.0)),
    );
    let hi = x - k * c(LN2HI);
    let lo = k * c(LN2LO);
    let r = hi - lo;
    let xx = r * r;
    let p = r - xx * (c(P1) + xx * (c(P2) + xx * (c(P3) + xx * (c(P4) + xx * c(P5)))));
    let y = c(1.0) + (r * p / (c(2.0) - p) - lo + hi);
    F64x4::blend(ax.mask(Cmp::Lt(TINY)), c(1.0) + x, y * pow2(k))
}

/// `ln x` for four lanes: `libm::log` step by step, for positive normal finite `x`; other lanes
/// send the batch through `libm::log`. Its constants by their bits, as e_log.c gives them.
#[inline]
pub(crate) fn ln4(x: F64x4) -> F64x4 {
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    const LG1: f64 = f64::from_bits(0x3fe5_5555_5555_5593);
    const LG2: f64 = f64::from_bits(0x3fd9_9999_9997_fa04);
    const LG3: f64 = f64::from_bits(0x3fd2_4924_9422_9359);
    const LG4: f64 = f64::from_bits(0x3fcc_71c5_1d8e_78af);
    const LG5: f64 = f64::from_bits(0x3fc7_4664_96cb_03de);
    const LG6: f64 = f64::from_bits(0x3fc3_9a09_d078_c69f);
    const LG7: f64 = f64::from_bits(0x3fc2_f112_df3e_5244);
    let c = F64x4::c;
    let normal =
        x.0.simd_ge(f64x4::splat(f64::MIN_POSITIVE)) & x.0.simd_lt(f64x4::splat(f64::INFINITY));
    if !normal.all() {
        return x.map(libm::log);
    }
    // x = m·2^k with m in [sqrt(2)/2, sqrt(2)], on the high word as e_log.c does: the offset
    // moves the mantissa boundary to sqrt(2)/2, the exponent field then holds k + 1023.
    const OFFSET: u64 = (0x3ff0_0000 - 0x3fe6_a09e) << 32;
    let ui = x.bits() + u64x4::splat(OFFSET);
    // k, converted exactly through the low bits of 2^52.
    let dk = F64x4::from_bits((ui >> 52) | u64x4::splat(0x4330_0000_0000_0000))
        - c(4_503_599_627_370_496.0 + 1023.0);
    let m = F64x4::from_bits(
        (ui & u64x4::splat(0x000f_ffff_ffff_ffff)) + u64x4::splat(0x3fe6_a09e << 32),
    );
    let f = m - c(1.0);
    let hfsq = c(0.5) * f * f;
    let s = f / (c(2.0) + f);
    let z = s * s;
    let w = z * z;
    let t1 = w * (c(LG2) + w * (c(LG4) + w * c(LG6)));
    let t2 = z * (c(LG1) + w * (c(LG3) + w * (c(LG5) + w * c(LG7))));
    let r = t2 + t1;
    s * (hfsq + r) + dk * c(LN2_LO) - hfsq + f + dk * c(LN2_HI)
}

#[cfg(test)]
mod tests {
    use super::super::tests::{check_lanes, spread};
    use super::*;

    #[test]
    fn exp_is_libm_bit_for_bit() {
        let special = [
            0.0,
            -0.0,
            1e-300,
            0.34657359027997264,
            1.0397207708399179,
            -1.0397207708399179,
            708.39,
            -708.39,
            -745.2,
            710.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let xs = spread(20_000, -750.0, 750.0)
            .chain(spread(20_000, -2.0, 2.0))
            .chain(spread(4_000, -1e-7, 1e-7))
            .chain(special);
        check_lanes(exp4, libm::exp, xs);
        // One special lane among ordinary ones.
        check_lanes(exp4, libm::exp, [0.5, f64::NAN, -3.0, 800.0].into_iter());
    }

    #[test]
    fn ln_is_libm_bit_for_bit() {
        let special = [
            1.0,
            0.0,
            -1.0,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            f64::INFINITY,
            f64::NAN,
            core::f64::consts::SQRT_2,
            core::f64::consts::FRAC_1_SQRT_2,
        ];
        let xs = spread(20_000, 0.0, 10.0)
            .chain(spread(20_000, 0.5, 2.0))
            .chain(spread(4_000, 0.0, 1e-300))
            .chain(spread(4_000, 0.0, 1e300))
            .chain(special);
        check_lanes(ln4, libm::log, xs);
    }
}
