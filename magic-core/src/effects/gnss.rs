//! The GNSS effects: their checks against a network and their terms in F (uₑ ×S, uₙ ×S, uᵥ ×S
//! in mm), and F with effects, [`mogi_with_effects`].

use super::Effect;
use crate::mogi::{self, Network, Station};
use crate::real::sin_cos::sin_cos_turn;
use crate::{EffectFault, Error, Real};

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
            Effect::Illumination { .. } | Effect::BandOffset { .. } => {
                Err(self.invalid(EffectFault::NotGnss))
            }
            _ => Err(self.invalid(EffectFault::Parameters)),
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
                // The phase within the year and its sine and cosine, in R (see [`sin_cos_turn`];
                // no f64 arithmetic on the board), the semiannual terms by the double-angle
                // formulas.
                let (sn, cs) = sin_cos_turn::<R>((t / R::c(YEAR_DAYS)).fraction());
                let basis = [sn, cs, R::c(2.0) * sn * cs, cs * cs - sn * sn];
                // The four terms written out: as a loop, the board's size-optimised build kept
                // it (about 37 instructions per channel against about 20).
                let k = |c: &[u8], i: usize| {
                    R::c_f32(f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]))
                };
                for (o, c) in out.iter_mut().zip(coef.0.chunks_exact(16)) {
                    *o += k(c, 0) * basis[0]
                        + k(c, 4) * basis[1]
                        + k(c, 8) * basis[2]
                        + k(c, 12) * basis[3];
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
            // (The family as a constant: through `self.family()` this arm cost the board ~55
            // executed instructions per inversion, measured under QEMU.)
            Effect::Illumination { .. } => return Err(not_gnss("illumination")),
            Effect::BandOffset { .. } => return Err(not_gnss("band_offset")),
        }
        Ok(())
    }
}

/// [`EffectFault::NotGnss`] for an effect of family `family`.
#[cold]
#[inline(never)]
fn not_gnss(family: &'static str) -> Error {
    Error::InvalidEffect {
        family,
        fault: EffectFault::NotGnss,
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
    mogi_terms_of(stations, effects, params, t_day, out, true)
}

/// [`mogi_with_effects`] for any [`Network`] (e.g. the stations of a model file) if `dated`,
/// else F₀: F without its dated terms ([`Effect::is_dated`]), the part of F a variant-C model's
/// correction sees, with F = F₀ + [`dated_part_of`].
pub fn mogi_terms_of<R: Real, N: Network + ?Sized>(
    stations: &N,
    effects: &[Effect<'_>],
    params: &[R],
    t_day: f64,
    out: &mut [R],
    dated: bool,
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
        if dated || !e.is_dated() {
            e.apply_to(stations, lat, t_day, out)?;
        }
        k += n;
    }
    Ok(())
}

/// F's dated terms ([`Effect::is_dated`]: steps and drifts) on day `t_day`, written over `out`
/// (zero where the model declares none).
pub fn dated_part_of<R: Real, N: Network + ?Sized>(
    stations: &N,
    effects: &[Effect<'_>],
    t_day: f64,
    out: &mut [R],
) -> Result<(), Error> {
    out.fill(R::zero());
    for e in effects.iter().filter(|e| e.is_dated()) {
        e.apply_to(stations, &[], t_day, out)?;
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
        // ∂u_E(station 0)/∂t_E = 1, ∂u_U(station 1)/∂k = z − z_ref = 0.15, up to the f32
        // rounding of z_ref in the effect (measured 1.2e-8; half an f32 ulp of 0.45 is 1.5e-8).
        assert_eq!(out[0].d[4], 1.0);
        let z_ref_rounding = 0.45 * f32::EPSILON as f64 / 2.0;
        assert!((out[5].d[7] - 0.15).abs() <= z_ref_rounding);
    }

    #[test]
    fn two_extra_sources_each_take_their_own_volume() {
        let at = |x_km, y_km, depth_km| Effect::SecondSource {
            x_km,
            y_km,
            depth_km,
        };
        let (a, b) = (at(4.0, -1.0, 3.0), at(-6.0, 5.0, 5.0));
        // Main source off (ΔV 0); then each extra source alone, and both.
        let run = |effects: &[Effect<'_>], latent: &[f64]| {
            let mut p = [0.0, 0.0, 5.0, 0.0, 0.0, 0.0];
            p[4..4 + latent.len()].copy_from_slice(latent);
            let mut out = [0.0f64; 6];
            mogi_with_effects(&NET, effects, &p[..4 + latent.len()], f64::NAN, &mut out).unwrap();
            out
        };
        let (ua, ub) = (run(&[a], &[1.5]), run(&[b], &[-2.0]));
        let both = run(&[a, b], &[1.5, -2.0]);
        for i in 0..6 {
            assert_eq!(both[i], ua[i] + ub[i], "channel {i}");
        }
        assert!(ua.iter().chain(&ub).all(|&u| u != 0.0));
    }

    #[test]
    fn steps_add_each_from_its_epoch() {
        let step = |station, epoch_day, offset_mm| Effect::Step {
            station,
            epoch_day,
            offset_mm,
        };
        let effects = [
            step(0, 100.0, [1.0, 2.0, 3.0]),
            step(1, 150.0, [-1.0, 0.5, 4.0]),
            step(0, 200.0, [0.25, 0.0, -3.0]),
        ];
        // Main source off (ΔV 0): only the steps move the stations.
        let at = |t: f64| {
            let mut out = [0.0f64; 6];
            mogi_with_effects(&NET, &effects, &[0.0, 0.0, 5.0, 0.0], t, &mut out).unwrap();
            out
        };
        assert_eq!(at(99.0), [0.0; 6]);
        assert_eq!(at(149.0), [1.0, 0.0, 2.0, 0.0, 3.0, 0.0]);
        assert_eq!(at(150.0), [1.0, -1.0, 2.0, 0.5, 3.0, 4.0]);
        assert_eq!(at(200.0), [1.25, -1.0, 2.0, 0.5, 0.0, 4.0]);
    }

    #[test]
    fn the_dated_part_is_f_less_its_source_and_latent_terms() {
        let effects = [
            Effect::CommonMode,
            Effect::Step {
                station: 1,
                epoch_day: 100.0,
                offset_mm: [-1.0, 0.5, 4.0],
            },
        ];
        let p = [1.0, -2.0, 4.0, 0.3, 2.0, -1.0, 3.0];
        let (mut f, mut dated) = ([0.0f64; 6], [9.0f64; 6]);
        // Before the epoch nothing is dated (the common mode is latent); after it, the step.
        dated_part_of(&NET[..], &effects, 99.0, &mut dated).unwrap();
        assert_eq!(dated, [0.0; 6]);
        dated_part_of(&NET[..], &effects, 100.0, &mut dated).unwrap();
        assert_eq!(dated, [0.0, -1.0, 0.0, 0.5, 0.0, 4.0]);
        let mut before = [0.0f64; 6];
        mogi_with_effects(&NET, &effects, &p, 99.0, &mut before).unwrap();
        mogi_with_effects(&NET, &effects, &p, 100.0, &mut f).unwrap();
        // F₀, F without its dated terms, is the same before and after the epoch.
        let mut undated = [0.0f64; 6];
        mogi_terms_of(&NET[..], &effects, &p, 100.0, &mut undated, false).unwrap();
        assert_eq!(undated, before);
        for i in 0..6 {
            // (Equal up to the rounding of adding the step and taking it off again.)
            assert!((f[i] - dated[i] - before[i]).abs() <= 1e-12, "channel {i}");
        }
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
