//! The GNSS effects: their checks against a network and their terms in F (uₑ ×S, uₙ ×S, uᵥ ×S
//! in mm), and F with effects, [`mogi_with_effects`].

use super::Effect;
use crate::mogi::{self, Network, Station};
use crate::{Error, Real};

const TWO_PI: f64 = core::f64::consts::TAU;
const YEAR_DAYS: f64 = 365.25;

impl Effect<'_> {
    /// Checks the effect against a network of `n_stations`.
    pub fn validate(&self, n_stations: usize) -> Result<(), Error> {
        let n_obs = 3 * n_stations;
        let finite = |v: f32| v.is_finite();
        match *self {
            Effect::CommonMode => Ok(()),
            Effect::Elevation { z_ref_km } if finite(z_ref_km) => Ok(()),
            Effect::SecondSource {
                x_km,
                y_km,
                depth_km,
            } if finite(x_km) && finite(y_km) && depth_km > 0.0 => Ok(()),
            Effect::Seasonal { coef } if coef.0.len() == 16 * n_obs && coef.iter().all(finite) => {
                Ok(())
            }
            Effect::Step {
                station,
                epoch_day,
                offset_mm,
            } if (station as usize) < n_stations
                && finite(epoch_day)
                && offset_mm.iter().all(|v| v.is_finite()) =>
            {
                Ok(())
            }
            Effect::Drift { t0_day, rate }
                if finite(t0_day) && rate.0.len() == 4 * n_obs && rate.iter().all(finite) =>
            {
                Ok(())
            }
            Effect::Illumination { .. } | Effect::BandOffset { .. } => Err(Error::InvalidModel(
                "illumination and band offsets belong to RTM models, not to a GNSS network",
            )),
            _ => Err(Error::InvalidModel(
                "effect parameters invalid or sized for another network",
            )),
        }
    }

    /// Adds the effect to `out` (uₑ ×S, uₙ ×S, uᵥ ×S in mm). `latent` holds this effect's latent
    /// variables; `t_day` the date (needed by fitted effects).
    pub fn apply<R: Real>(
        &self,
        stations: &[Station],
        latent: &[R],
        t_day: f64,
        out: &mut [R],
    ) -> Result<(), Error> {
        self.apply_to(stations, latent, t_day, out)
    }

    /// [`Effect::apply`] for any [`Network`] (e.g. the stations of a model file).
    ///
    /// Everything is computed in `R` (f32 on the board): the date enters through one reduction of
    /// `t_day` to the phase within the year (seasonal) or to years since the reference (drift).
    pub fn apply_to<R: Real, N: Network + ?Sized>(
        &self,
        stations: &N,
        latent: &[R],
        t_day: f64,
        out: &mut [R],
    ) -> Result<(), Error> {
        let s = stations.n_stations();
        if out.len() != 3 * s || latent.len() != self.n_latent() {
            return Err(Error::SizeMismatch {
                what: "effect inputs",
                expected: 3 * s,
                found: out.len(),
            });
        }
        // The date in R (exact for whole days in f32): every use of it below is R arithmetic,
        // so the board's f32 build does no soft-float f64 work here.
        let t = R::c(t_day);
        if self.needs_time() && !t.is_finite() {
            return Err(Error::OutOfRange {
                what: "date (the model has time-dependent effects)",
            });
        }
        match *self {
            Effect::CommonMode => {
                // One translation per component (E, N, U), each added to every station.
                for (comp, &l) in out.chunks_exact_mut(s.max(1)).zip(latent) {
                    for o in comp {
                        *o += l;
                    }
                }
            }
            Effect::Elevation { z_ref_km } => {
                let (Some(&k), Some(up)) = (latent.first(), out.get_mut(2 * s..)) else {
                    return Ok(());
                };
                let z_ref = R::c(z_ref_km as f64);
                for (i, o) in up.iter_mut().enumerate() {
                    *o += k * (R::c(stations.station(i).z_km) - z_ref);
                }
            }
            Effect::SecondSource {
                x_km,
                y_km,
                depth_km,
            } => {
                let Some(&dv) = latent.first() else {
                    return Ok(());
                };
                let p = [
                    R::c(x_km as f64),
                    R::c(y_km as f64),
                    R::c(depth_km as f64),
                    dv,
                ];
                let Some((ue, rest)) = out.split_at_mut_checked(s) else {
                    return Ok(());
                };
                let (un, uu) = rest.split_at_mut(rest.len() / 2);
                for (i, ((e, n), u)) in ue.iter_mut().zip(un).zip(uu).enumerate() {
                    let d = mogi::displacement(&stations.station(i), &p);
                    *e += d[0];
                    *n += d[1];
                    *u += d[2];
                }
            }
            Effect::Seasonal { coef } => {
                // The phase within the year and its sine and cosine, in R (see `sin_cos_turn`;
                // no f64 arithmetic on the board), the semiannual terms by the double-angle
                // formulas.
                let (sn, cs) = sin_cos_turn::<R>(fraction(t / R::c(YEAR_DAYS)));
                let basis = [sn, cs, R::c(2.0) * sn * cs, cs * cs - sn * sn];
                for (o, c) in out.iter_mut().zip(coef.0.chunks_exact(16)) {
                    let mut v = R::zero();
                    for (b, cb) in basis.iter().zip(c.chunks_exact(4)) {
                        let x = f32::from_le_bytes([cb[0], cb[1], cb[2], cb[3]]);
                        v += R::c(x as f64) * *b;
                    }
                    *o += v;
                }
            }
            Effect::Step {
                station,
                epoch_day,
                offset_mm,
            } => {
                if t >= R::c(epoch_day as f64) {
                    let i = station as usize;
                    for (k, off) in offset_mm.iter().enumerate() {
                        if let Some(o) = out.get_mut(k * s + i) {
                            *o += R::c(*off as f64);
                        }
                    }
                }
            }
            Effect::Drift { t0_day, rate } => {
                let years = (t - R::c(t0_day as f64)) / R::c(YEAR_DAYS);
                for (o, r) in out.iter_mut().zip(rate.iter()) {
                    *o += R::c(r as f64) * years;
                }
            }
            Effect::Illumination { .. } | Effect::BandOffset { .. } => {
                return Err(Error::InvalidModel(
                    "illumination and band offsets belong to RTM models, not to a GNSS network",
                ))
            }
        }
        Ok(())
    }
}

/// `x − ⌊x⌋` in `R`, exactly, by subtracting powers of two (Sterbenz: each subtraction is exact),
/// for |x| < 2³¹: no conversion to an integer, which in f32 would go through f64 (soft-float on
/// the board).
fn fraction<R: Real>(x: R) -> R {
    let neg = x < R::zero();
    let mut f = if neg { -x } else { x };
    for k in (0..31).rev() {
        let p = R::c((1u32 << k) as f64);
        if f >= p {
            f -= p;
        }
    }
    if neg && f > R::zero() {
        R::one() - f
    } else {
        f
    }
}

/// `sin(2πf)` and `cos(2πf)` for a fraction of a turn `f` in [0, 1), in `R`: the nearest quarter
/// turn is taken out, and the rest, |x| ≤ π/4, goes through the Taylor series
/// up to x¹⁷ / x¹⁸ (truncation below 1e-19), evaluated in `R`. No library call: on the board
/// (`R = f32`) libm's `sinf`/`cosf` would bring their f64 argument reduction (about 3 KB of
/// flash) for this one term; on the host (`R = f64`) the result is within a few ulps of libm's.
fn sin_cos_turn<R: Real>(f: R) -> (R, R) {
    // 1 / ((2k)(2k + 1)), k = 1..=8, and 1 / ((2k − 1)(2k)), k = 1..=9.
    const S: [f64; 8] = [
        1.0 / 6.0,
        1.0 / 20.0,
        1.0 / 42.0,
        1.0 / 72.0,
        1.0 / 110.0,
        1.0 / 156.0,
        1.0 / 210.0,
        1.0 / 272.0,
    ];
    const C: [f64; 9] = [
        1.0 / 2.0,
        1.0 / 12.0,
        1.0 / 30.0,
        1.0 / 56.0,
        1.0 / 90.0,
        1.0 / 132.0,
        1.0 / 182.0,
        1.0 / 240.0,
        1.0 / 306.0,
    ];
    // The nearest quarter turn, by comparisons (the bounds are exact in binary).
    let q = [0.125, 0.375, 0.625, 0.875]
        .iter()
        .filter(|&&b| f >= R::c(b))
        .count();
    let quarter = [0.0, 0.25, 0.5, 0.75, 1.0].get(q).copied().unwrap_or(0.0);
    let x = R::c(TWO_PI) * (f - R::c(quarter));
    let x2 = x * x;
    // Horner on x²: sin x = x (1 − x²/(2·3) (1 − x²/(4·5) (…))), cos x = 1 − x²/(1·2) (…).
    let mut s = R::one();
    for &k in S.iter().rev() {
        s = R::one() - x2 * s * R::c(k);
    }
    let mut c = R::one();
    for &k in C.iter().rev() {
        c = R::one() - x2 * c * R::c(k);
    }
    let s = x * s;
    match q % 4 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// F with effects: the Mogi field of `params[..4]` plus every effect, whose latent variables
/// follow in `params[4..]` in the order of `effects`.
pub fn mogi_with_effects<R: Real>(
    stations: &[Station],
    effects: &[Effect<'_>],
    params: &[R],
    t_day: f64,
    out: &mut [R],
) -> Result<(), Error> {
    mogi_with_effects_of(stations, effects, params, t_day, out)
}

/// [`mogi_with_effects`] for any [`Network`] (e.g. the stations of a model file).
pub fn mogi_with_effects_of<R: Real, N: Network + ?Sized>(
    stations: &N,
    effects: &[Effect<'_>],
    params: &[R],
    t_day: f64,
    out: &mut [R],
) -> Result<(), Error> {
    let p: [R; mogi::N_PARAMS] = params
        .get(..mogi::N_PARAMS)
        .and_then(|s| s.try_into().ok())
        .ok_or(Error::SizeMismatch {
            what: "mogi parameters",
            expected: mogi::N_PARAMS,
            found: params.len(),
        })?;
    mogi::field_of(stations, &p, out)?;
    let mut k = mogi::N_PARAMS;
    for e in effects {
        let n = e.n_latent();
        let lat = params.get(k..k + n).ok_or(Error::SizeMismatch {
            what: "effect latent variables",
            expected: k + n,
            found: params.len(),
        })?;
        e.apply_to(stations, lat, t_day, out)?;
        k += n;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quant::LeF32;
    use crate::Dual;

    const NET: [Station; 2] = [
        Station {
            x_km: 1.0,
            y_km: 2.0,
            z_km: 0.3,
        },
        Station {
            x_km: -3.0,
            y_km: 0.5,
            z_km: 0.6,
        },
    ];

    #[test]
    fn latent_effects_are_linear_with_exact_derivatives() {
        let effects = [Effect::CommonMode, Effect::Elevation { z_ref_km: 0.45 }];
        let p: [Dual<8>; 8] =
            core::array::from_fn(|i| Dual::var([0.5, 0.1, 6.0, 1.0, 2.0, -1.0, 3.0, 10.0][i], i));
        let mut out = [Dual::<8>::c(0.0); 6];
        mogi_with_effects(&NET, &effects, &p, f64::NAN, &mut out).unwrap();
        // ∂u_E(station 0)/∂t_E = 1, ∂u_U(station 1)/∂k = z − z_ref = 0.15
        assert_eq!(out[0].d[4], 1.0);
        assert!((out[5].d[7] - 0.15).abs() < 1e-6);
    }

    #[test]
    fn fractions_of_a_year() {
        for x in [
            0.0,
            0.25,
            1.0,
            54.75,
            54.999_999,
            -0.25,
            -1.0,
            -3.5,
            1e6 + 0.5,
            16_777_215.0,
        ] {
            assert_eq!(fraction(x), x - libm::floor(x), "{x}");
            let x32 = x as f32;
            assert_eq!(fraction(x32), x32 - libm::floorf(x32), "{x}");
        }
    }

    #[test]
    fn seasonal_sine_and_cosine_match_libm() {
        let mut worst = 0f64;
        for i in 0..=4000 {
            let f = i as f64 / 4000.0 * 0.999_999_9;
            let (s, c) = sin_cos_turn::<f64>(f);
            let (s32, c32) = sin_cos_turn::<f32>(f as f32);
            let w = TWO_PI * f;
            worst = worst
                .max((s - libm::sin(w)).abs())
                .max((c - libm::cos(w)).abs());
            assert!(
                (s32 as f64 - libm::sin(w)).abs() < 3e-7
                    && (c32 as f64 - libm::cos(w)).abs() < 3e-7
            );
        }
        assert!(worst < 1e-15, "{worst:e}");
    }

    #[test]
    fn time_effects_need_a_date() {
        let rate = [0u8; 24];
        let e = Effect::Drift {
            t0_day: 0.0,
            rate: LeF32(&rate),
        };
        let mut out = [0.0f64; 6];
        assert!(e.apply(&NET, &[], f64::NAN, &mut out).is_err());
        assert!(e.apply(&NET, &[], 10.0, &mut out).is_ok());
        let step = Effect::Step {
            station: 1,
            epoch_day: 100.0,
            offset_mm: [1.0, 2.0, 3.0],
        };
        step.apply(&NET, &[], 99.0, &mut out).unwrap();
        assert_eq!(out, [0.0; 6]);
        step.apply(&NET, &[], 100.0, &mut out).unwrap();
        assert_eq!(out, [0.0, 1.0, 0.0, 2.0, 0.0, 3.0]);
        assert!(Effect::Step {
            station: 2,
            epoch_day: 0.0,
            offset_mm: [0.0; 3]
        }
        .validate(2)
        .is_err());
    }
}
