//! Random draws the generators share: independent streams per seed and purpose, Gaussian
//! deviates, AR(1) series.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// A generator of its own for `seed` and a purpose (`salt`): the noise, the source history and
/// each injected effect draw from separate streams, so that adding an effect leaves the clean
/// data unchanged.
pub fn stream(seed: u64, salt: u64) -> StdRng {
    StdRng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ salt)
}

/// A standard Gaussian deviate (Box–Muller).
pub fn normal(rng: &mut StdRng) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// An AR(1) series of `n` values with time scale `tau` days (stationary start, unit
/// innovations).
pub fn ar1(rng: &mut StdRng, n: usize, tau: f64) -> Vec<f64> {
    ar1_phi(rng, n, (-1.0 / tau).exp(), 1.0)
}

/// An AR(1) series of `n` values, `x[t] = φ x[t−1] + σ ε` (stationary start).
pub fn ar1_phi(rng: &mut StdRng, n: usize, phi: f64, sigma: f64) -> Vec<f64> {
    let mut x = sigma * normal(rng) / (1.0 - phi * phi).sqrt();
    (0..n)
        .map(|_| {
            x = phi * x + sigma * normal(rng);
            x
        })
        .collect()
}

/// A value of magnitude in `[lo, hi)` with a random sign.
pub fn sym(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    let v = rng.random_range(lo..hi);
    if rng.random::<bool>() {
        v
    } else {
        -v
    }
}

/// Root mean square of `v` about its mean.
pub fn rms_about_mean(v: &[f64]) -> f64 {
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt()
}

/// `v` rounded to three decimals.
pub fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}
