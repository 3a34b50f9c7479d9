//! The exponential integral E1(x) = ∫₁^∞ e^(−xt)/t dt, x > 0.
//!
//! PROSPECT's leaf-layer transmissivity needs it (and its derivative −e^(−x)/x for training). For
//! x ≤ 1 the convergent power series E1 = −γ − ln x − Σ_{k≥1} (−x)^k / (k·k!) is summed; for x > 1
//! the continued fraction E1 = e^(−x) · 1/(x + 1 − 1/(x + 3 − 4/(x + 5 − …))) is evaluated by the
//! modified Lentz method (Abramowitz & Stegun 5.1.11 and 5.1.22). Both are summed to f64 round-off;
//! the stated bound is checked against the table in the tests.

/// Largest relative error of [`e1_f64`] against the test vectors.
pub const E1_MAX_REL_ERROR: f64 = 1e-14;

const EULER_GAMMA: f64 = 0.577_215_664_901_532_9;

/// E1(x) in double precision. Returns `+inf` at 0 and NaN for negative or NaN input.
pub fn e1_f64(x: f64) -> f64 {
    if x.is_nan() || x < 0.0 {
        return f64::NAN;
    }
    if x == 0.0 {
        return f64::INFINITY;
    }
    if x <= 1.0 {
        // −γ − ln x + Σ_{k≥1} (−1)^(k+1) x^k / (k·k!)
        let mut sum = 0.0;
        let mut term = 1.0; // x^k / k!
        for k in 1..=40 {
            let kf = k as f64;
            term *= -x / kf; // (−x)^k / k!
            let add = term / kf;
            sum -= add;
            if libm::fabs(add) < 1e-17 * libm::fabs(sum) {
                break;
            }
        }
        -EULER_GAMMA - libm::log(x) + sum
    } else {
        // Continued fraction, modified Lentz.
        let tiny = 1e-300;
        let mut b = x + 1.0;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..=200 {
            let fi = i as f64;
            let an = -fi * fi;
            b += 2.0;
            d = 1.0 / (an * d + b);
            c = b + an / c;
            let del = c * d;
            h *= del;
            if libm::fabs(del - 1.0) < 1e-16 {
                break;
            }
        }
        h * libm::exp(-x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (x, E1(x)) evaluated to 30 digits (arbitrary-precision arithmetic).
    const TEST_VECTORS: &[(f64, f64)] = &[
        (1e-6, 13.238_295_893_062_491),
        (0.1, 1.822_923_958_419_390_7),
        (0.5, 0.559_773_594_776_160_8),
        (1.0, 0.219_383_934_395_520_27),
        (1.5, 0.100_019_582_406_632_6),
        (2.0, 0.048_900_510_708_061_12),
        (5.0, 0.001_148_295_591_275_326),
        (10.0, 4.156_968_929_685_324e-6),
        (20.0, 9.835_525_290_649_886e-11),
    ];

    #[test]
    fn matches_table() {
        for &(x, want) in TEST_VECTORS {
            let got = e1_f64(x);
            let rel = libm::fabs(got - want) / want;
            assert!(rel <= E1_MAX_REL_ERROR, "E1({x}) = {got}, want {want}, rel {rel}");
        }
    }

    #[test]
    fn continuous_across_branch() {
        let a = e1_f64(1.0 - 1e-12);
        let b = e1_f64(1.0 + 1e-12);
        assert!(libm::fabs(a - b) < 1e-11);
    }

    #[test]
    fn edge_cases() {
        assert!(e1_f64(-1.0).is_nan());
        assert!(e1_f64(f64::NAN).is_nan());
        assert_eq!(e1_f64(0.0), f64::INFINITY);
        assert!(e1_f64(800.0) == 0.0);
    }
}
