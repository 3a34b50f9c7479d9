use super::*;
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};

/// `n` values of white (unit) plus AR(1) (`phi`, stationary variance `rho`) noise, times
/// `sd`, on consecutive days.
pub(super) fn noise(
    n: usize,
    phi: f64,
    rho: f64,
    sd: f64,
    rng: &mut rand::rngs::StdRng,
) -> Vec<f64> {
    let mut gauss = || {
        let (u, v): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    let mut a = rho.sqrt() * gauss();
    (0..n)
        .map(|_| {
            a = phi * a + (rho * (1.0 - phi * phi)).sqrt() * gauss();
            sd * (a + gauss())
        })
        .collect()
}

/// Channels side by side, row-major.
pub(super) fn rows(channels: &[Vec<f64>]) -> Vec<f64> {
    let n = channels[0].len();
    (0..n)
        .flat_map(|t| channels.iter().map(move |c| c[t]))
        .collect()
}

#[test]
fn the_noise_shape_and_levels_are_recovered() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let sds = [1.0, 2.0, 0.5, 1.5, 1.0, 3.0];
    let chans: Vec<Vec<f64>> = sds
        .iter()
        .map(|&s| noise(6000, 0.99, 8.0, s, &mut rng))
        .collect();
    let days: Vec<f64> = (0..6000).map(f64::from).collect();
    let (shape, levels) = fit_noise(&rows(&chans), sds.len(), &days).unwrap();
    // One record per channel: the persistence's time scale within 35 %, the ratio within a
    // factor 1.6, each level within 12 % (measured: see the message).
    let msg = format!("{shape:?} {levels:?}");
    assert!(((1.0 - shape.phi) / 0.01 - 1.0).abs() < 0.35, "{msg}");
    assert!((shape.rho / 8.0).ln().abs() < 0.47, "{msg}");
    for (l, s) in levels.iter().zip(sds) {
        assert!((l / (s * s) - 1.0).abs() < 0.12, "{msg}");
    }
}

/// The exact generalised least squares z of `g` along `u` under each channel's covariance
/// `level_c (I + ρ φ^|Δday|)`, each channel's mean free.
fn dense_z(
    r: &[f64],
    nc: usize,
    days: &[f64],
    shape: Shape,
    levels: &[f64],
    g: &[f64],
    u: &[f64],
) -> f64 {
    let n = days.len();
    let cov = DMatrix::from_fn(n, n, |i, j| {
        let d = (days[i] - days[j]).abs();
        let white = if i == j { 1.0 } else { 0.0 };
        white + shape.rho * shape.phi.powf(d)
    });
    let inv = cov.try_inverse().unwrap();
    let one = DVector::from_element(n, 1.0);
    let uv = DVector::from_column_slice(u);
    // u off the level in the Σ⁻¹ metric.
    let k = (one.transpose() * &inv * &uv)[0] / (one.transpose() * &inv * &one)[0];
    let uo = &uv - &one * k;
    let (mut num, mut den) = (0.0, 0.0);
    for c in 0..nc {
        let y = DVector::from_iterator(n, (0..n).map(|t| r[t * nc + c]));
        num += g[c] * (uo.transpose() * &inv * &y)[0] / levels[c];
        den += g[c] * g[c] * (uo.transpose() * &inv * &uo)[0] / levels[c];
    }
    num / den.sqrt()
}

/// Against the generalised least squares written out (dense covariance), on a record of
/// consecutive days and on one with gaps: the Kalman filter's innovations are exactly white.
#[test]
fn z_is_the_generalised_least_squares_z() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(2);
    let shape = Shape {
        phi: 0.97,
        rho: 6.0,
    };
    let levels: [f64; 3] = [1.0, 4.0, 0.25];
    let mut worst: f64 = 0.0;
    for gaps in [false, true] {
        let days: Vec<f64> = (0..420)
            .map(f64::from)
            .filter(|d| !gaps || !((150.0..170.0).contains(d) || (300.0..303.0).contains(d)))
            .collect();
        let n = days.len();
        let chans: Vec<Vec<f64>> = levels
            .iter()
            .map(|l| noise(n, shape.phi, shape.rho, l.sqrt(), &mut rng))
            .collect();
        let mut r = rows(&chans);
        let g = [0.8, -0.3, 1.2];
        // A change along the ramp from day 200, 2 noise sd in the first channel.
        let u = ramp(&days, 200.0);
        for t in 0..n {
            for c in 0..3 {
                r[t * 3 + c] += 2.0 * g[c] * u[t];
            }
        }
        let m = Matched::with_noise(&r, 3, &days, shape, &levels, |_| true).unwrap();
        for k in [0, 5, 14, m.onsets() - 1] {
            let want = dense_z(
                &r,
                3,
                &days,
                shape,
                &levels,
                &g,
                &ramp(&days, m.onset_days[k]),
            );
            let got = m.z(&g, k);
            worst = worst.max((got - want).abs() / want.abs().max(1.0));
        }
    }
    // Equal to rounding (measured below 1e-14).
    assert!(worst < 1e-10, "largest relative difference {worst}");
}

/// Calibrated: on records of the noise, each with its own fitted model, z has unit variance
/// at an onset mid-record; a change along the ramp is found at its onset.
#[test]
fn z_is_standard_on_noise_and_finds_a_change() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let days: Vec<f64> = (0..2000).map(f64::from).collect();
    let g = [1.0, -0.5, 0.7, 0.2];
    let z2: Vec<f64> = (0..200)
        .map(|_| {
            let chans: Vec<Vec<f64>> = (0..4)
                .map(|_| noise(2000, 0.99, 5.0, 1.0, &mut rng))
                .collect();
            let m = Matched::new(&rows(&chans), 4, &days, |_| true).unwrap();
            m.z(&g, m.onsets() / 2).powi(2)
        })
        .collect();
    let mean = z2.iter().sum::<f64>() / z2.len() as f64;
    // 200 draws of χ²₁: the mean within 0.3 of 1 (about 3 standard errors).
    assert!((mean - 1.0).abs() < 0.3, "mean z² {mean}");
    let mut chans: Vec<Vec<f64>> = (0..4)
        .map(|_| noise(2000, 0.99, 5.0, 1.0, &mut rng))
        .collect();
    let u = ramp(&days, 1200.0);
    for (c, ch) in chans.iter_mut().enumerate() {
        ch.iter_mut()
            .zip(&u)
            .for_each(|(v, s)| *v += 10.0 * g[c] * s);
    }
    let m = Matched::new(&rows(&chans), 4, &days, |_| true).unwrap();
    let zs: Vec<f64> = (0..m.onsets()).map(|k| m.z(&g, k).abs()).collect();
    let best = (0..zs.len())
        .max_by(|&a, &b| zs[a].total_cmp(&zs[b]))
        .unwrap();
    assert!(
        (m.onset_days[best] - 1200.0).abs() <= 30.0,
        "onset {}",
        m.onset_days[best]
    );
    assert!(zs[best] > 6.0, "z {}", zs[best]);
}

#[test]
fn onsets_keep_to_the_edges_and_the_filter() {
    let days: Vec<f64> = (0..1000).map(f64::from).collect();
    let r = vec![0.0; 1000];
    let shape = Shape { phi: 0.9, rho: 1.0 };
    let m = Matched::with_noise(&r, 1, &days, shape, &[1.0], |_| true).unwrap();
    assert_eq!(m.onset_days.first(), Some(&ONSET_EDGE_DAYS));
    assert!(*m.onset_days.last().unwrap() <= 999.0 - ONSET_EDGE_DAYS);
    let late = Matched::with_noise(&r, 1, &days, shape, &[1.0], |d| d > 900.0).unwrap();
    assert!(late.onset_days.iter().all(|d| *d > 900.0));
    assert!(Matched::with_noise(&r, 1, &days, shape, &[1.0], |_| false).is_none());
    // A pattern of zeros is not identified; zero residuals give z 0.
    assert_eq!(m.z(&[0.0], 3), 0.0);
    assert_eq!(m.z(&[1.0], 3), 0.0);
    assert_eq!(m.z(&[1.0], m.onsets()), 0.0, "an onset beyond the table");
}
