//! The checks a decoded model passes before anything runs on it: sizes and values against the
//! compiled limits and against each other, per problem (a GNSS network for Mogi, the bands and
//! fixed inputs of INFORM), then the networks and bounds of the variant.

use super::{
    AnyProblem, Model, Names, Problem, Problems, Variant, MAX_OBS, MAX_PARAMS, MAX_STATIONS,
};
use crate::mogi::{self, Stations};
use crate::nn::{validate_chain, Activation};
use crate::rtm::{Fixed, N_BANDS, N_LEARNED};
use crate::{BoundFault, Error, LayerFault, Net};

impl Model<'_> {
    /// Checks every size and value against the compiled limits and against each other.
    pub fn validate(&self) -> Result<(), Error> {
        self.validate_for::<AnyProblem>()
    }

    /// [`Model::validate`] for a build that links only the forward models of `P`.
    pub fn validate_for<P: Problems>(&self) -> Result<(), Error> {
        let n_obs = self.check_observations()?;
        let n_phys = match &self.problem {
            Problem::Mogi { stations, names } => self.check_mogi(*stations, *names, n_obs)?,
            Problem::Rtm { .. } if !P::RTM => return Err(Error::WrongProblem),
            Problem::Rtm { .. } => self.check_rtm(n_obs)?,
        };
        self.check_networks::<P>(n_obs, n_phys)
    }

    /// The observation count, standardisation and residual threshold; returns the count.
    fn check_observations(&self) -> Result<usize, Error> {
        let n_obs = self.n_obs();
        if n_obs == 0 || n_obs > MAX_OBS {
            return Err(Error::CountOutOfRange {
                what: "observations",
                found: n_obs,
                min: 1,
                max: MAX_OBS as u16,
            });
        }
        if self.obs_mean.0.len() != 4 * n_obs {
            return Err(Error::SizeMismatch {
                what: "observation mean bytes",
                expected: 4 * n_obs,
                found: self.obs_mean.0.len(),
            });
        }
        if self.obs_scale.0.len() != self.obs_mean.0.len() {
            return Err(Error::SizeMismatch {
                what: "obs_scale",
                expected: n_obs,
                found: self.obs_scale.len(),
            });
        }
        if let Some(index) = self.obs_mean.iter().position(|m| !m.is_finite()) {
            return Err(Error::NonFinite {
                what: "observation mean",
                index,
            });
        }
        let positive = |s: f32| s.is_finite() && s > 0.0;
        if !self.obs_scale.iter().all(positive) {
            return Err(Error::OutOfRange {
                what: "observation scale (not positive)",
            });
        }
        if !(self.residual_threshold.is_finite() && self.residual_threshold >= 0.0) {
            return Err(Error::OutOfRange {
                what: "residual threshold",
            });
        }
        Ok(n_obs)
    }

    /// A GNSS network: stations, names, channel count and effects; returns the number of
    /// physical variables (the source's and the effects' latent ones).
    fn check_mogi(
        &self,
        stations: Stations<'_>,
        names: Names<'_>,
        n_obs: usize,
    ) -> Result<usize, Error> {
        if stations.len() * mogi::STATION_BYTES != stations.0.len() {
            return Err(Error::SizeMismatch {
                what: "station bytes",
                expected: stations.len() * mogi::STATION_BYTES,
                found: stations.0.len(),
            });
        }
        if names.len() != stations.len() {
            return Err(Error::SizeMismatch {
                what: "station names",
                expected: stations.len(),
                found: names.len(),
            });
        }
        if !names.well_formed() {
            return Err(Error::OutOfRange {
                what: "station name (1 to 8 bytes)",
            });
        }
        if stations.is_empty() {
            return Err(Error::CountOutOfRange {
                what: "stations",
                found: 0,
                min: 1,
                max: MAX_STATIONS as u16,
            });
        }
        if n_obs != 3 * stations.len() {
            return Err(Error::SizeMismatch {
                what: "observations (3 per station)",
                expected: 3 * stations.len(),
                found: n_obs,
            });
        }
        let finite =
            |s: mogi::Station| s.x_km.is_finite() && s.y_km.is_finite() && s.z_km.is_finite();
        if let Some(index) = stations.iter().position(|s| !finite(s)) {
            return Err(Error::NonFinite {
                what: "station position",
                index,
            });
        }
        for e in &self.effects {
            e.validate(stations.len())?;
        }
        Ok(mogi::N_PARAMS + self.effects.iter().map(|e| e.n_latent()).sum::<usize>())
    }

    /// A forest-spectra model: band mask, packed tables, effects and fixed inputs (run once
    /// through INFORM at the middle of the bounds); returns the number of physical variables.
    fn check_rtm(&self, n_obs: usize) -> Result<usize, Error> {
        let Problem::Rtm {
            bands,
            fixed,
            geometry,
            ..
        } = &self.problem
        else {
            return Err(Error::WrongProblem);
        };
        if *bands >> N_BANDS != 0 {
            return Err(Error::OutOfRange {
                what: "RTM band mask (bands beyond B12)",
            });
        }
        if bands.count_ones() as usize != n_obs {
            return Err(Error::SizeMismatch {
                what: "observations (one per observed band)",
                expected: bands.count_ones() as usize,
                found: n_obs,
            });
        }
        let packed = self.problem.packed()?;
        for e in &self.effects {
            e.validate_rtm(n_obs, *geometry)?;
        }
        if let Some(index) = fixed_inputs(fixed).iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "RTM fixed input",
                index,
            });
        }
        // The fixed inputs must be accepted by the forward model (angles, soil, LIDF row, …):
        // run it once at the middle of the bounds.
        let usable =
            self.bounds.len() == N_LEARNED && self.bounds.iter().all(|b| b[0] > 0.0 && b[0] < b[1]);
        if self.variant != Variant::A && usable {
            let mut z = [0f64; N_LEARNED];
            for (zi, b) in z.iter_mut().zip(self.bounds.iter()) {
                *zi = 0.5 * (b[0] as f64 + b[1] as f64);
            }
            let mut y = [0f64; N_BANDS];
            let out = y.get_mut(..n_obs).unwrap_or(&mut []);
            packed.forward_learned(&z, fixed, *geometry, out)?;
        }
        Ok(N_LEARNED)
    }

    /// The encoder and decoder of the variant against the observation count and the `n_phys`
    /// physical variables, and the bounds of B and C.
    fn check_networks<P: Problems>(&self, n_obs: usize, n_phys: usize) -> Result<(), Error> {
        let n_params = self.n_params();
        if self.variant == Variant::A {
            if n_params == 0 || n_params > MAX_PARAMS {
                return Err(Error::CountOutOfRange {
                    what: "latent variables",
                    found: n_params,
                    min: 1,
                    max: MAX_PARAMS as u16,
                });
            }
            validate_chain(&self.encoder, n_obs, n_params, Net::Encoder)?;
            return validate_chain(&self.decoder, n_params, n_obs, Net::Decoder);
        }
        validate_chain(&self.encoder, n_obs, n_phys, Net::Encoder)?;
        // (Not empty: the chain was validated.)
        let last = self.encoder.len().saturating_sub(1);
        if let Some(head) = self.encoder.last() {
            if head.act != Activation::Sigmoid || head.is_int8() {
                return Err(Error::InvalidLayer {
                    net: Net::Encoder,
                    layer: last as u8, // < MAX_LAYERS
                    fault: LayerFault::Head,
                });
            }
        }
        self.check_bounds::<P>(n_phys)?;
        if self.variant == Variant::C {
            validate_chain(&self.decoder, n_obs, n_obs, Net::Decoder)
        } else if !self.decoder.is_empty() {
            Err(Error::CountOutOfRange {
                what: "decoder layers",
                found: self.decoder.len(),
                min: 0,
                max: 0,
            })
        } else {
            Ok(())
        }
    }

    /// The bounds of B and C: one per physical variable, finite with min < max; positive where
    /// the physics needs it (a Mogi source's depth, every INFORM variable).
    fn check_bounds<P: Problems>(&self, n_phys: usize) -> Result<(), Error> {
        if self.bounds.len() != n_phys {
            return Err(Error::SizeMismatch {
                what: "bounds",
                expected: n_phys,
                found: self.bounds.len(),
            });
        }
        let bound = |index: usize, fault| Error::InvalidBound {
            index: index as u8, // < MAX_PARAMS
            fault,
        };
        let usable = |b: &[f32; 2]| b[0].is_finite() && b[1].is_finite() && b[0] < b[1];
        if let Some(i) = self.bounds.iter().position(|b| !usable(b)) {
            return Err(bound(i, BoundFault::Empty));
        }
        match self.problem {
            Problem::Mogi { .. } if self.bounds.get(2).is_none_or(|b| b[0] <= 0.0) => {
                Err(bound(2, BoundFault::NotPositive))
            }
            Problem::Rtm { .. } if P::RTM => match self.bounds.iter().position(|b| b[0] <= 0.0) {
                Some(i) => Err(bound(i, BoundFault::NotPositive)),
                None => Ok(()),
            },
            _ => Ok(()),
        }
    }
}

/// The fixed INFORM inputs in one array (to find a non-finite one).
fn fixed_inputs(f: &Fixed) -> [f64; 13] {
    [
        f.car,
        f.anth,
        f.cbrown,
        f.cp,
        f.cbc,
        f.type_lidf,
        f.lidf,
        f.hspot,
        f.psoil,
        f.tts,
        f.tto,
        f.psi,
        f.sd,
    ]
}
