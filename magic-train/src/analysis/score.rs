//! Held-out scores: the share of residual variance a prediction explains once scaled by one
//! least-squares weight λ ≥ 0 (so that a family never scores below zero, and noise scores are
//! χ²-like).

/// Reduction of the squared residual by a prediction scaled by its least-squares weight λ ≥ 0:
/// `max(0, Σ r·p)² / Σ p²` from `(Σ r·p, Σ p²)`. One fitted scalar per prediction; the
/// surrogates fit it too.
pub fn weighted_gain((rp, pp): (f64, f64)) -> f64 {
    if rp > 0.0 && pp > 0.0 {
        rp * rp / pp
    } else {
        0.0
    }
}

/// `max(0, Σ⟨r, p⟩)² / (Σ‖p‖² Σ‖r‖²)` over paired rows: the share of `r`'s squared norm the
/// weighted prediction `p` explains.
pub fn share(r: &[&[f64]], p: &[Vec<f64>]) -> f64 {
    let (mut rp, mut pp, mut rr) = (0.0, 0.0, 0.0);
    for (ri, pi) in r.iter().zip(p) {
        for (a, b) in ri.iter().zip(pi) {
            rp += a * b;
            pp += b * b;
            rr += a * a;
        }
    }
    if rr <= 0.0 {
        return 0.0;
    }
    weighted_gain((rp, pp)) / rr
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_perfect_prediction_explains_everything_and_a_wrong_sign_nothing() {
        let r = [1.0, -2.0, 0.5];
        let p = vec![vec![2.0, -4.0, 1.0]];
        assert!((share(&[&r], &p) - 1.0).abs() < 1e-15);
        let q = vec![vec![-2.0, 4.0, -1.0]];
        assert_eq!(share(&[&r], &q), 0.0);
        assert_eq!(weighted_gain((1.0, 0.0)), 0.0);
    }
}
