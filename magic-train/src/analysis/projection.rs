//! Projection off F's tangent space: what F, linearised around the model's typical state, cannot
//! produce whatever its variables. Residuals and candidate patterns are both projected, so that a
//! pattern the encoder could mimic by moving its variables does not count as a discovery; fitted
//! constants are de-projected so that adding the effect to F reproduces the fit.

use nalgebra::{DMatrix, DVector};

/// `g` without its part in the span of the orthonormal `basis`.
pub fn project(basis: &[Vec<f64>], g: &[f64]) -> Vec<f64> {
    let mut out = g.to_vec();
    for q in basis {
        let d: f64 = q.iter().zip(&out).map(|(a, b)| a * b).sum();
        for (o, v) in out.iter_mut().zip(q) {
            *o -= d * v;
        }
    }
    out
}

/// The share (in norm) of `v` beyond the span of the orthonormal `basis`; 0 for a zero `v`.
///
/// ```
/// use magic_train::analysis::projection::share_beyond;
/// let basis = [vec![1.0, 0.0, 0.0]];
/// assert_eq!(share_beyond(&basis, &[3.0, 4.0, 0.0]), 0.8);
/// assert_eq!(share_beyond(&basis, &[0.0; 3]), 0.0);
/// ```
pub fn share_beyond(basis: &[Vec<f64>], v: &[f64]) -> f64 {
    let norm2 = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
    let n = norm2(v);
    if n > 0.0 {
        (norm2(&project(basis, v)) / n).sqrt()
    } else {
        0.0
    }
}

/// Each coordinate's leverage under the orthonormal `basis` (`n` coordinates): the diagonal of
/// the projector onto its span, `Σ_q q_c²`. Noise of unit variance on every coordinate keeps
/// `1 − h_c` of it on coordinate `c` once projected off the span.
///
/// ```
/// use magic_train::analysis::projection::leverage;
/// let s = 0.5f64.sqrt();
/// let h = leverage(&[vec![s, s, 0.0]], 3);
/// assert!((h[0] - 0.5).abs() < 1e-12 && (h[1] - 0.5).abs() < 1e-12 && h[2] == 0.0);
/// ```
pub fn leverage(basis: &[Vec<f64>], n: usize) -> Vec<f64> {
    (0..n)
        .map(|c| basis.iter().map(|q| q.get(c).map_or(0.0, |v| v * v)).sum())
        .collect()
}

/// A column for [`orthonormal`], with its largest entry (absolute) as its scale.
///
/// ```
/// use magic_train::analysis::projection::scaled;
/// assert_eq!(scaled(vec![0.5, -2.0, 1.0]), (vec![0.5, -2.0, 1.0], 2.0));
/// ```
pub fn scaled(col: Vec<f64>) -> (Vec<f64>, f64) {
    let s = col.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    (col, s)
}

/// An orthonormal basis of the span of `columns` (modified Gram–Schmidt, `passes` times over the
/// basis so far); a column whose remainder is below `rel_tol` of its largest entry (`scale`) is
/// dependent on the others and dropped.
pub fn orthonormal(columns: &[(Vec<f64>, f64)], rel_tol: f64, passes: usize) -> Vec<Vec<f64>> {
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for (col, scale) in columns {
        let mut v = col.clone();
        for _ in 0..passes.max(1) {
            for q in &basis {
                let d: f64 = q.iter().zip(&v).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(q).for_each(|(x, y)| *x -= d * y);
            }
        }
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n > rel_tol * scale.max(1e-300) && n > 0.0 {
            v.iter_mut().for_each(|x| *x /= n);
            basis.push(v);
        }
    }
    basis
}

/// `P⊥ E v`: the projected response on all `nc` channels of values `v` on channels `chans`.
pub fn projected_response(basis: &[Vec<f64>], nc: usize, chans: &[usize], v: &[f64]) -> Vec<f64> {
    let mut full = vec![0.0; nc];
    for (c, x) in chans.iter().zip(v) {
        full[*c] = *x;
    }
    project(basis, &full)
}

/// The values `v` on `chans` whose projection, `P⊥ E v` with `E` the injection of those channels,
/// equals `d` on them: `(Eᵀ P⊥ E) v = d`. A family fitted channel by channel on projected
/// residuals sees only `Eᵀ P⊥ E v`; this undoes that so that the effect's constants are those
/// that, added to F, reproduce the fit. Falls back to `d` when the channels are almost inside F's
/// tangent space (the effect is then mostly absorbed by the encoder anyway).
pub fn deproject(basis: &[Vec<f64>], chans: &[usize], d: &[f64]) -> Vec<f64> {
    let n = chans.len();
    if n == 0 {
        return vec![];
    }
    let mut m = DMatrix::<f64>::identity(n, n);
    for q in basis {
        for i in 0..n {
            for j in 0..n {
                m[(i, j)] -= q[chans[i]] * q[chans[j]];
            }
        }
    }
    let norm = |x: &[f64]| x.iter().map(|a| a * a).sum::<f64>().sqrt();
    match m.lu().solve(&DVector::from_column_slice(d)) {
        Some(v) if v.iter().all(|x| x.is_finite()) && norm(v.as_slice()) <= 5.0 * norm(d) => {
            v.iter().copied().collect()
        }
        _ => d.to_vec(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
    }

    #[test]
    fn deprojection_inverts_the_projection() {
        let nc = 9;
        let basis = orthonormal(&[(noise(nc, 1), 1.0), (noise(nc, 2), 1.0)], 1e-9, 1);
        assert_eq!(basis.len(), 2);
        let chans = [0usize, 3, 6];
        let v = [0.7, -1.2, 2.0];
        let resp = projected_response(&basis, nc, &chans, &v);
        let d: Vec<f64> = chans.iter().map(|&c| resp[c]).collect();
        let back = deproject(&basis, &chans, &d);
        for (a, b) in back.iter().zip(&v) {
            assert!((a - b).abs() < 1e-9);
        }
    }

    #[test]
    fn dependent_columns_are_dropped_and_projection_is_orthogonal() {
        let a = noise(6, 3);
        let b: Vec<f64> = a.iter().map(|x| 2.0 * x).collect();
        let basis = orthonormal(&[(a.clone(), 1.0), (b, 2.0)], 1e-9, 2);
        assert_eq!(basis.len(), 1);
        let p = project(&basis, &a);
        assert!(p.iter().all(|x| x.abs() < 1e-12));
    }
}
