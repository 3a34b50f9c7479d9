//! Order statistics, spread and rank correlation over `f64` slices (NaN-free input assumed;
//! `total_cmp` keeps any NaN from panicking a sort).

/// Median (mean of the two middle values for an even count); 0 for no values. Sorts `v`.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Share of a standard normal within ±1: the quantile of |error| / sd that a calibrated sd
/// matches (the map's and the bootstrap's calibration factors are this quantile).
pub const ONE_SIGMA: f64 = 0.682_689_492;

/// The `q` quantile with linear interpolation between order statistics; 0 for no values.
pub fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (s.len() - 1) as f64;
    let (i, f) = (pos.floor() as usize, pos - pos.floor());
    if i + 1 < s.len() {
        s[i] * (1.0 - f) + s[i + 1] * f
    } else {
        s[i]
    }
}

/// P(X ≤ k) for X ~ Binomial(n, p), summed in log space (no underflow for large `n`).
pub fn binomial_cdf(k: usize, n: usize, p: f64) -> f64 {
    if k >= n || p <= 0.0 {
        return 1.0;
    }
    if p >= 1.0 {
        return 0.0;
    }
    let (lp, lq) = (p.ln(), (1.0 - p).ln());
    let mut ln_choose = 0.0; // ln C(n, 0)
    let mut sum = 0.0;
    for i in 0..=k {
        if i > 0 {
            ln_choose += ((n - i + 1) as f64).ln() - (i as f64).ln();
        }
        sum += (ln_choose + i as f64 * lp + (n - i) as f64 * lq).exp();
    }
    sum.min(1.0)
}

/// The exact (Clopper–Pearson) two-sided interval of a binomial proportion, `k` successes of
/// `n`, at confidence `level` (e.g. 0.95): the `p` at which `k` or more, and `k` or fewer, would
/// be seen with probability (1 − level) / 2. `(0, 1)` for `n = 0`.
pub fn clopper_pearson(k: usize, n: usize, level: f64) -> (f64, f64) {
    let a = (1.0 - level) / 2.0;
    if n == 0 {
        return (0.0, 1.0);
    }
    // The cdf falls as p grows: bisect for the p where `f(p)` crosses `target`.
    let bisect = |f: &dyn Fn(f64) -> f64, target: f64| {
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for _ in 0..64 {
            let mid = 0.5 * (lo + hi);
            if f(mid) > target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    };
    let lower = if k == 0 {
        0.0
    } else {
        // P(X ≥ k) = a, i.e. P(X ≤ k − 1) = 1 − a.
        bisect(&|p| binomial_cdf(k - 1, n, p), 1.0 - a)
    };
    let upper = if k >= n {
        1.0
    } else {
        bisect(&|p| binomial_cdf(k, n, p), a)
    };
    (lower, upper)
}

/// Sample standard deviation; 0 for fewer than two values.
pub fn sd(v: &[f64]) -> f64 {
    if v.len() < 2 {
        return 0.0;
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

/// Mean and sample standard deviation.
pub fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len().max(1) as f64;
    (v.iter().sum::<f64>() / n, sd(v))
}

/// `mean ± std` with four decimals, or `-` for no values.
pub fn mean_std_text(v: &[f64]) -> String {
    if v.is_empty() {
        "-".to_string()
    } else {
        let (m, s) = mean_std(v);
        format!("{m:.4} ± {s:.4}")
    }
}

/// Ranks (0-based, ties get their average rank).
fn ranks(v: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
    let mut r = vec![0.0; v.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && v[idx[j + 1]] == v[idx[i]] {
            j += 1;
        }
        for k in i..=j {
            r[idx[k]] = (i + j) as f64 / 2.0;
        }
        i = j + 1;
    }
    r
}

/// Spearman rank correlation (average ranks for ties); NaN with fewer than 3 pairs.
///
/// ```
/// use magic_train::numerics::spearman;
/// assert_eq!(spearman(&[1.0, 2.0, 3.0, 4.0], &[10.0, 20.0, 25.0, 100.0]), 1.0);
/// assert!(spearman(&[1.0, 2.0], &[2.0, 1.0]).is_nan());
/// ```
pub fn spearman(a: &[f64], b: &[f64]) -> f64 {
    if a.len() < 3 || a.len() != b.len() {
        return f64::NAN;
    }
    let (ra, rb) = (ranks(a), ranks(b));
    let n = a.len() as f64;
    let (ma, mb) = (ra.iter().sum::<f64>() / n, rb.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in ra.iter().zip(&rb) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    sab / (saa * sbb).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binomial_cdf_sums_the_probabilities() {
        // 10 fair coins, 3 heads or fewer: (1 + 10 + 45 + 120) / 1024.
        assert!((binomial_cdf(3, 10, 0.5) - 176.0 / 1024.0).abs() < 1e-14);
        assert_eq!(binomial_cdf(10, 10, 0.3), 1.0);
        assert_eq!(binomial_cdf(0, 10, 0.0), 1.0);
        assert_eq!(binomial_cdf(9, 10, 1.0), 0.0);
        // Large n in log space: P(X ≤ 4 999) for Binomial(10 000, 0.5), just under a half.
        let c = binomial_cdf(4_999, 10_000, 0.5);
        assert!((c - 0.496).abs() < 1e-3, "{c}");
    }

    /// Clopper–Pearson 95 % intervals as tabulated (four decimals; max error 5e-5 + rounding).
    const CLOPPER_PEARSON_95: [(usize, usize, f64, f64); 5] = [
        (0, 10, 0.0, 0.3085),
        (5, 10, 0.1871, 0.8129),
        (9, 10, 0.5550, 0.9975),
        (10, 10, 0.6915, 1.0),
        (1, 20, 0.0013, 0.2487),
    ];

    #[test]
    fn clopper_pearson_matches_the_tables() {
        for (k, n, lo, hi) in CLOPPER_PEARSON_95 {
            let (l, h) = clopper_pearson(k, n, 0.95);
            assert!(
                (l - lo).abs() < 1e-4 && (h - hi).abs() < 1e-4,
                "{k}/{n}: {l} {h}"
            );
        }
        assert_eq!(clopper_pearson(0, 0, 0.95), (0.0, 1.0));
    }

    #[test]
    fn order_statistics() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert_eq!(median(&mut []), 0.0);
        assert_eq!(quantile(&[0.0, 10.0], 0.25), 2.5);
        assert_eq!(quantile(&[5.0], 0.95), 5.0);
        assert!((sd(&[1.0, 2.0, 3.0, 4.0]) - (5.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert_eq!(mean_std_text(&[]), "-");
    }

    #[test]
    fn spearman_uses_average_ranks_for_ties() {
        // Ranks (0.5, 0.5, 2, 3) against (0, 1, 2, 3): ρ = 0.9487 (≈ 3/√10).
        let r = spearman(&[1.0, 1.0, 2.0, 3.0], &[1.0, 2.0, 3.0, 4.0]);
        assert!((r - 3.0 / 10f64.sqrt()).abs() < 1e-12, "{r}");
        assert!((spearman(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]) + 1.0).abs() < 1e-15);
    }
}
