//! The Mogi source under a station network, with declared effects, as a [`Physics`] for the
//! trainer: values and the exact Jacobian (dual numbers) of the core's `mogi_with_effects`.

use crate::model::OwnedEffect;
use crate::physics::Physics;
use magic_core::effects::{dated_part_of, mogi_with_effects, Effect, MAX_EFFECTS};
use magic_core::mogi::{self, Station};
use magic_core::{Dual, Error};

/// Largest number of variables the trainer differentiates for (source plus effect latents).
const MAX_DUAL: usize = 16;

/// The Mogi source under a station network, with declared effects.
#[derive(Clone, Debug)]
pub struct MogiPhysics {
    /// Stations in channel order.
    pub stations: Vec<Station>,
    /// Declared effects (latent variables follow the source's four).
    effects: Vec<OwnedEffect>,
    /// The effects' arrays as the core borrows them, made once (not per row).
    bytes: Vec<Vec<u8>>,
}

impl MogiPhysics {
    /// The source with declared `effects` (none: the paper's F).
    pub fn new(stations: Vec<Station>, effects: Vec<OwnedEffect>) -> Self {
        let bytes = effects.iter().map(OwnedEffect::bytes).collect();
        MogiPhysics {
            stations,
            effects,
            bytes,
        }
    }

    /// The declared effects.
    pub fn effects(&self) -> &[OwnedEffect] {
        &self.effects
    }

    /// Runs `f` on the core's view of the effects (on the stack: no allocation per row).
    fn with_effects<T>(
        &self,
        f: impl FnOnce(&[Effect<'_>]) -> Result<T, Error>,
    ) -> Result<T, Error> {
        let mut eff: heapless::Vec<Effect<'_>, MAX_EFFECTS> = heapless::Vec::new();
        for (e, b) in self.effects.iter().zip(&self.bytes) {
            eff.push(e.borrow(b)).map_err(|_| Error::SizeMismatch {
                what: "effects",
                expected: MAX_EFFECTS,
                found: self.effects.len(),
            })?;
        }
        f(&eff)
    }
}

impl Physics for MogiPhysics {
    fn n_params(&self) -> usize {
        mogi::N_PARAMS + self.effects.iter().map(|e| e.n_latent()).sum::<usize>()
    }
    fn n_obs(&self) -> usize {
        3 * self.stations.len()
    }
    fn forward(&self, p: &[f64], t: f64, out: &mut [f64]) -> Result<(), Error> {
        self.with_effects(|eff| mogi_with_effects(&self.stations, eff, p, t, out))
    }
    fn dated(&self, t: f64, out: &mut [f64]) -> Result<(), Error> {
        self.with_effects(|eff| dated_part_of(&self.stations[..], eff, t, out))
    }
    fn has_dated(&self) -> bool {
        self.effects.iter().any(|e| e.borrow(&[]).is_dated())
    }
    fn jacobian(&self, p: &[f64], t: f64, out: &mut [f64], jac: &mut [f64]) -> Result<(), Error> {
        let n = self.n_params();
        if n > MAX_DUAL || p.len() != n {
            return Err(Error::SizeMismatch {
                what: "variables",
                expected: n.min(MAX_DUAL),
                found: p.len(),
            });
        }
        if out.len() != self.n_obs() || jac.len() != out.len() * n {
            return Err(Error::SizeMismatch {
                what: "jacobian",
                expected: self.n_obs() * n,
                found: jac.len(),
            });
        }
        let mut pd = [Dual::<MAX_DUAL>::constant(0.0); MAX_DUAL];
        for (j, v) in p.iter().enumerate() {
            pd[j] = Dual::var(*v, j);
        }
        let mut o = [Dual::<MAX_DUAL>::constant(0.0); magic_core::model_file::MAX_OBS];
        let o = o.get_mut(..out.len()).ok_or(Error::SizeMismatch {
            what: "observations",
            expected: magic_core::model_file::MAX_OBS,
            found: out.len(),
        })?;
        self.with_effects(|eff| mogi_with_effects(&self.stations, eff, &pd[..n], t, o))?;
        for (c, oc) in o.iter().enumerate() {
            out[c] = oc.v;
            jac[c * n..(c + 1) * n].copy_from_slice(&oc.d[..n]);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::synth;

    #[test]
    fn has_dated_says_whether_the_dated_terms_can_be_nonzero() {
        let stations = synth::generate(synth::Scenario::Clean, 1)
            .problem
            .network
            .stations;
        let step = OwnedEffect::Step {
            station: 1,
            epoch_day: 14_000.0,
            offset_mm: [1.0, 2.0, 3.0],
        };
        let drift = OwnedEffect::Drift {
            t0_day: 14_000.0,
            rate: vec![1.0; 3 * stations.len()],
        };
        let annual = OwnedEffect::Seasonal {
            coef: vec![1.0; 4 * 3 * stations.len()],
        };
        let cases = [
            (vec![], false),
            (vec![OwnedEffect::CommonMode, annual.clone()], false),
            (vec![OwnedEffect::CommonMode, step], true),
            (vec![annual, drift], true),
        ];
        for (effects, dated) in cases {
            let phys = MogiPhysics::new(stations.clone(), effects.clone());
            assert_eq!(phys.has_dated(), dated, "{effects:?}");
            // On a day after both the step's epoch and the drift's reference day.
            let mut out = vec![0.0; phys.n_obs()];
            phys.dated(14_100.0, &mut out).unwrap();
            assert_eq!(out.iter().any(|v| *v != 0.0), dated, "{effects:?}");
        }
    }
}
