//! Surrogate residuals for chance levels: randomised copies that keep the noise's structure and
//! destroy an effect family's.
//!
//! * [`PhaseSurrogates`]: one random phase per frequency, shared by all channels (or by groups of
//!   channels), so every channel's spectrum and every cross-spectrum are kept — for families that
//!   are functions of the date (seasonal terms, steps, drifts);
//! * [`flip_reverse`]: every station's series given a random sign and direction of time — for
//!   families that are network-coherent patterns, which this destroys while keeping each
//!   station's own series whole;
//! * permutations and sign flips of labels are done by the families themselves (`rand`'s
//!   `shuffle`).

use rand::rngs::StdRng;
use rand::Rng;
use rayon::prelude::*;
use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

/// Phase-randomised surrogates of a block of rows (`r[t * nc + c]`).
pub struct PhaseSurrogates {
    nc: usize,
    n: usize,
    /// Each channel's spectrum.
    spectra: Vec<Vec<Complex64>>,
}

impl PhaseSurrogates {
    /// The spectra of the `nc` channels of `r`.
    pub fn new(r: &[f64], nc: usize) -> PhaseSurrogates {
        let n = r.len() / nc.max(1);
        let fft = FftPlanner::<f64>::new().plan_fft_forward(n.max(1));
        let spectra = (0..nc)
            .into_par_iter()
            .map(|c| {
                let mut x: Vec<Complex64> =
                    (0..n).map(|t| Complex64::new(r[t * nc + c], 0.0)).collect();
                if n > 0 {
                    fft.process(&mut x);
                }
                x
            })
            .collect();
        PhaseSurrogates { nc, n, spectra }
    }

    /// One surrogate: a random phase per frequency shared by all channels.
    pub fn draw(&self, rng: &mut StdRng) -> Vec<f64> {
        self.draw_grouped(rng, 1, &|_| 0)
    }

    /// One surrogate with independent random phases for each of `groups` groups of channels
    /// (`group(c)`): spectra and cross-spectra within a group are kept, groups become
    /// independent.
    pub fn draw_grouped(
        &self,
        rng: &mut StdRng,
        groups: usize,
        group: &dyn Fn(usize) -> usize,
    ) -> Vec<f64> {
        let n = self.n;
        if n == 0 {
            return vec![];
        }
        // Hermitian rotations: e^{iφ_k} with φ_{n−k} = −φ_k, φ_0 = φ_{n/2} = 0 (a real series).
        let rots: Vec<Vec<Complex64>> = (0..groups.max(1))
            .map(|_| {
                let rot: Vec<Complex64> = (0..n)
                    .map(|k| {
                        if k == 0 || 2 * k == n {
                            Complex64::new(1.0, 0.0)
                        } else {
                            Complex64::from_polar(1.0, rng.random_range(0.0..std::f64::consts::TAU))
                        }
                    })
                    .collect();
                (0..n)
                    .map(|k| if 2 * k > n { rot[n - k].conj() } else { rot[k] })
                    .collect()
            })
            .collect();
        let ifft = FftPlanner::<f64>::new().plan_fft_inverse(n);
        let mut out = vec![0.0; n * self.nc];
        let scale = 1.0 / n as f64;
        // Two real channels per complex inverse transform.
        for c0 in (0..self.nc).step_by(2) {
            let c1 = (c0 + 1 < self.nc).then_some(c0 + 1);
            let r0 = &rots[group(c0)];
            let mut spec: Vec<Complex64> = (0..n)
                .map(|k| {
                    let a = self.spectra[c0][k] * r0[k];
                    let b = c1.map_or(Complex64::new(0.0, 0.0), |c| {
                        self.spectra[c][k] * rots[group(c)][k]
                    });
                    a + Complex64::i() * b
                })
                .collect();
            ifft.process(&mut spec);
            for t in 0..n {
                out[t * self.nc + c0] = spec[t].re * scale;
                if let Some(c) = c1 {
                    out[t * self.nc + c] = spec[t].im * scale;
                }
            }
        }
        out
    }
}

/// Every station's channels (channel `c` belongs to station `c % ns`) multiplied by a random sign
/// and, at random, reversed in time — not all stations given the same transform, which would
/// keep the network's coherence. For noise that is Gaussian, stationary and independent between
/// stations each transform is as likely as the data, whatever its spectrum.
pub fn flip_reverse(r: &[f64], nc: usize, ns: usize, rng: &mut StdRng) -> Vec<f64> {
    let t_n = r.len() / nc.max(1);
    let mut ops: Vec<(f64, bool)> = Vec::new();
    while ops.is_empty() || (ns > 1 && ops.iter().all(|o| *o == ops[0])) {
        ops = (0..ns)
            .map(|_| {
                (
                    if rng.random::<bool>() { 1.0 } else { -1.0 },
                    rng.random::<bool>(),
                )
            })
            .collect();
    }
    let mut out = vec![0.0; r.len()];
    for t in 0..t_n {
        for c in 0..nc {
            let (sign, rev) = ops[c % ns];
            out[t * nc + c] = sign * r[(if rev { t_n - 1 - t } else { t }) * nc + c];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
    }

    fn spectrum(v: &[f64], nc: usize, c: usize) -> Vec<Complex64> {
        let n = v.len() / nc;
        let mut x: Vec<Complex64> = (0..n).map(|t| Complex64::new(v[t * nc + c], 0.0)).collect();
        FftPlanner::<f64>::new().plan_fft_forward(n).process(&mut x);
        x
    }

    #[test]
    fn phase_surrogates_keep_spectra_and_cross_spectra() {
        for (n, nc) in [(64usize, 3usize), (101, 2)] {
            let r = noise(n * nc, 5);
            let ps = PhaseSurrogates::new(&r, nc);
            let s = ps.draw(&mut StdRng::seed_from_u64(9));
            assert!(s.iter().all(|v| v.is_finite()));
            for c in 0..nc {
                let (a, b) = (spectrum(&r, nc, c), spectrum(&s, nc, c));
                for k in 0..n {
                    assert!(
                        (a[k].norm() - b[k].norm()).abs() < 1e-9,
                        "n {n} c {c} k {k}"
                    );
                }
            }
            let (a0, a1, b0, b1) = (
                spectrum(&r, nc, 0),
                spectrum(&r, nc, 1),
                spectrum(&s, nc, 0),
                spectrum(&s, nc, 1),
            );
            for k in 0..n {
                let (x, y) = (a0[k] * a1[k].conj(), b0[k] * b1[k].conj());
                assert!((x - y).norm() < 1e-8, "cross-spectrum at {k}");
            }
            assert!(r.iter().zip(&s).map(|(a, b)| (a - b).abs()).sum::<f64>() > 1.0);
        }
    }

    #[test]
    fn flip_reverse_keeps_each_station_series_up_to_sign_and_time() {
        let (ns, nc, t_n) = (3usize, 9usize, 20usize);
        let r = noise(t_n * nc, 1);
        let s = flip_reverse(&r, nc, ns, &mut StdRng::seed_from_u64(4));
        for c in 0..nc {
            let a: Vec<f64> = (0..t_n).map(|t| r[t * nc + c]).collect();
            let b: Vec<f64> = (0..t_n).map(|t| s[t * nc + c]).collect();
            let same = |sgn: f64, rev: bool| {
                (0..t_n).all(|t| (b[t] - sgn * a[if rev { t_n - 1 - t } else { t }]).abs() < 1e-15)
            };
            assert!(same(1.0, false) || same(-1.0, false) || same(1.0, true) || same(-1.0, true));
        }
    }
}
