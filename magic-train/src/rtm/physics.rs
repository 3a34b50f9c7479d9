//! INFORM as a [`Physics`] for the trainer: the 7 learned variables `[N, cab, cw, cm, LAI, LAIu,
//! fc]` → the observed Sentinel-2 bands (reflectance), over the same packed rows the model file
//! carries (in f64 here), with the core's exact Jacobian.
//!
//! The day number `t` is passed by [`crate::physics::PhysicsOp`]; it matters only with the
//! illumination effect (each spectrum's own sun, `magic_core::effects::rtm_fixed_at`); without
//! it the geometry is the fixed one of the model (the paper's sun zenith 30°, nadir view).
//!
//! The Jacobian costs about 3.5 times the values, so the op's forward pass computes both while
//! training and its backward pass reuses them ([`JacobianReuse`]).

use crate::model::OwnedEffect;
use crate::physics::{JacobianReuse, Physics};
use crate::rtm::tables::PackedRows;
use magic_core::rtm::{Fixed, Geometry, N_LEARNED};
use magic_core::Error;

/// INFORM over packed f64 rows with fixed inputs and a geometry mode.
#[derive(Clone, Debug)]
pub struct RtmPhysics {
    /// Table rows of the observed bands (f64).
    pub rows: PackedRows,
    /// Fixed inputs.
    pub fixed: Fixed,
    /// Geometry mode.
    pub geometry: Geometry,
    /// Declared effects (illumination, band offsets).
    pub effects: Vec<OwnedEffect>,
    /// The band offsets of the effects, summed (reflectance; empty without).
    offsets: Vec<f64>,
    /// Jacobians of the op's forward pass kept for its backward pass.
    reuse: JacobianReuse,
}

/// The fixed inputs of the oracle and the paper (A.3): [`Fixed::default`].
pub fn paper_fixed() -> Fixed {
    Fixed::default()
}

fn learned(p: &[f64]) -> Result<[f64; N_LEARNED], Error> {
    p.try_into().map_err(|_| Error::SizeMismatch {
        what: "RTM variables",
        expected: N_LEARNED,
        found: p.len(),
    })
}

impl RtmPhysics {
    /// The model over `rows` (checks the rows once).
    pub fn new(rows: PackedRows, fixed: Fixed, geometry: Geometry) -> Result<Self, Error> {
        rows.model()?;
        Ok(RtmPhysics {
            rows,
            fixed,
            geometry,
            effects: vec![],
            offsets: vec![],
            reuse: JacobianReuse::default(),
        })
    }

    /// The same model with declared effects (checked as an RTM model checks them).
    pub fn with_effects(mut self, effects: Vec<OwnedEffect>) -> Result<Self, Error> {
        let n = self.n_obs();
        let mut offsets = vec![];
        for e in &effects {
            let bytes = e.bytes();
            e.borrow(&bytes).validate_rtm(n, self.geometry)?;
            if let OwnedEffect::BandOffset { offset } = e {
                offsets.resize(n, 0.0);
                for (o, v) in offsets.iter_mut().zip(offset) {
                    *o += *v as f64;
                }
            }
        }
        self.effects = effects;
        self.offsets = offsets;
        Ok(self)
    }

    /// The fixed inputs of an observation on day `t` (the paper's fixed sun without effects).
    pub fn fixed_at(&self, t: f64) -> Result<Fixed, Error> {
        // One effect at a time: no allocation on the training path (the sun reads no bytes).
        self.effects.iter().try_fold(self.fixed, |f, e| {
            magic_core::effects::rtm_fixed_at(&[e.borrow(&[])], &f, t)
        })
    }
}

impl Physics for RtmPhysics {
    fn n_params(&self) -> usize {
        N_LEARNED
    }
    fn n_obs(&self) -> usize {
        self.rows.bands.len()
    }
    fn forward(&self, p: &[f64], t: f64, out: &mut [f64]) -> Result<(), Error> {
        self.rows
            .model()?
            .forward_learned(&learned(p)?, &self.fixed_at(t)?, self.geometry, out)?;
        out.iter_mut().zip(&self.offsets).for_each(|(o, v)| *o += v);
        Ok(())
    }
    fn jacobian(&self, p: &[f64], t: f64, out: &mut [f64], jac: &mut [f64]) -> Result<(), Error> {
        let n = self.n_obs();
        if jac.len() != n * N_LEARNED {
            return Err(Error::SizeMismatch {
                what: "jacobian",
                expected: n * N_LEARNED,
                found: jac.len(),
            });
        }
        let mut j = [[0.0; N_LEARNED]; 16];
        self.rows.model()?.jacobian(
            &learned(p)?,
            &self.fixed_at(t)?,
            self.geometry,
            out,
            &mut j[..n],
        )?;
        for (c, row) in j[..n].iter().enumerate() {
            jac[c * N_LEARNED..(c + 1) * N_LEARNED].copy_from_slice(row);
        }
        Ok(())
    }
    fn jacobian_reuse(&self) -> Option<&JacobianReuse> {
        Some(&self.reuse)
    }
}
