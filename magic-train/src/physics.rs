//! The bridge between magic-core's forward models and candle's autograd.
//!
//! [`PhysicsOp`] is a candle custom op whose forward pass evaluates a core forward model row by
//! row (rayon over the batch) and whose backward pass multiplies the incoming gradient by the
//! model's exact Jacobian (forward-mode duals in the core). There is no second implementation of
//! the physics in the trainer.

use candle_core::{CpuStorage, CustomOp1, Layout, Shape, Tensor};
use magic_core::mogi::{self, Station};
use rayon::prelude::*;
use std::sync::Arc;

/// A forward model the trainer can differentiate through.
pub trait Physics: Send + Sync {
    /// Number of physical variables.
    fn n_params(&self) -> usize;
    /// Number of outputs.
    fn n_obs(&self) -> usize;
    /// Values: `out` has `n_obs` entries.
    fn forward(&self, p: &[f64], out: &mut [f64]) -> Result<(), magic_core::Error>;
    /// Values and Jacobian (`jac` row-major, `n_obs × n_params`).
    fn jacobian(&self, p: &[f64], out: &mut [f64], jac: &mut [f64]) -> Result<(), magic_core::Error>;
}

/// The Mogi source under a station network.
#[derive(Clone, Debug)]
pub struct MogiPhysics {
    /// Stations in channel order.
    pub stations: Vec<Station>,
}

impl Physics for MogiPhysics {
    fn n_params(&self) -> usize {
        mogi::N_PARAMS
    }
    fn n_obs(&self) -> usize {
        3 * self.stations.len()
    }
    fn forward(&self, p: &[f64], out: &mut [f64]) -> Result<(), magic_core::Error> {
        let p: [f64; 4] = p.try_into().map_err(|_| magic_core::Error::SizeMismatch {
            what: "mogi parameters",
            expected: 4,
            found: p.len(),
        })?;
        mogi::field(&self.stations, &p, out)
    }
    fn jacobian(&self, p: &[f64], out: &mut [f64], jac: &mut [f64]) -> Result<(), magic_core::Error> {
        let p: [f64; 4] = p.try_into().map_err(|_| magic_core::Error::SizeMismatch {
            what: "mogi parameters",
            expected: 4,
            found: p.len(),
        })?;
        let mut j = vec![[0.0; 4]; out.len()];
        mogi::field_jacobian(&self.stations, &p, out, &mut j)?;
        for (dst, src) in jac.chunks_exact_mut(4).zip(&j) {
            dst.copy_from_slice(src);
        }
        Ok(())
    }
}

/// The candle op applying a [`Physics`] to a `(batch, n_params)` f32 tensor.
#[derive(Clone)]
pub struct PhysicsOp(pub Arc<dyn Physics>);

fn core_err(e: magic_core::Error) -> candle_core::Error {
    candle_core::Error::Msg(format!("forward model: {e}"))
}

impl CustomOp1 for PhysicsOp {
    fn name(&self) -> &'static str {
        "physics"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let (b, p) = layout.shape().dims2()?;
        let (start, end) = layout
            .contiguous_offsets()
            .ok_or_else(|| candle_core::Error::Msg("physics op needs a contiguous input".into()))?;
        let input: Vec<f64> = match storage {
            CpuStorage::F32(v) => v[start..end].iter().map(|x| *x as f64).collect(),
            CpuStorage::F64(v) => v[start..end].to_vec(),
            _ => return Err(candle_core::Error::Msg("physics op takes f32 or f64".into())),
        };
        let n = self.0.n_obs();
        let mut out = vec![0f64; b * n];
        out.par_chunks_mut(n)
            .zip(input.par_chunks(p))
            .try_for_each(|(o, z)| self.0.forward(z, o))
            .map_err(core_err)?;
        let storage = match storage {
            CpuStorage::F64(_) => CpuStorage::F64(out),
            _ => CpuStorage::F32(out.into_iter().map(|x| x as f32).collect()),
        };
        Ok((storage, Shape::from((b, n))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let (b, p) = arg.dims2()?;
        let n = self.0.n_obs();
        let z = arg.to_dtype(candle_core::DType::F64)?.flatten_all()?.to_vec1::<f64>()?;
        let g = grad.to_dtype(candle_core::DType::F64)?.flatten_all()?.to_vec1::<f64>()?;
        let mut gz = vec![0f64; b * p];
        gz.par_chunks_mut(p)
            .enumerate()
            .try_for_each(|(i, gi)| {
                let mut out = vec![0f64; n];
                let mut jac = vec![0f64; n * p];
                self.0.jacobian(&z[i * p..(i + 1) * p], &mut out, &mut jac)?;
                for c in 0..n {
                    let gc = g[i * n + c];
                    for j in 0..p {
                        gi[j] += gc * jac[c * p + j];
                    }
                }
                Ok(())
            })
            .map_err(core_err)?;
        let t = Tensor::from_vec(gz, (b, p), arg.device())?.to_dtype(arg.dtype())?;
        Ok(Some(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn gradient_through_op_matches_finite_differences() {
        let phys: Arc<dyn Physics> = Arc::new(MogiPhysics {
            stations: vec![
                Station { x_km: -4.0, y_km: 6.0, z_km: 0.3 },
                Station { x_km: 10.0, y_km: 0.5, z_km: 0.4 },
            ],
        });
        let dev = Device::Cpu;
        let z0 = [1.0f64, -0.5, 6.0, 2.0];
        let z = Var::from_vec(z0.to_vec(), (1, 4), &dev).unwrap();
        let y = z.as_tensor().apply_op1(PhysicsOp(phys.clone())).unwrap();
        let loss = y.sqr().unwrap().sum_all().unwrap();
        let grads = loss.backward().unwrap();
        let g = grads.get(&z).unwrap().flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let f = |p: &[f64]| {
            let mut o = vec![0.0; 6];
            phys.forward(p, &mut o).unwrap();
            o.iter().map(|v| v * v).sum::<f64>()
        };
        for j in 0..4 {
            let h = 1e-6;
            let (mut a, mut b) = (z0, z0);
            a[j] += h;
            b[j] -= h;
            let fd = (f(&a) - f(&b)) / (2.0 * h);
            assert!((g[j] - fd).abs() <= 1e-6 * fd.abs().max(1.0), "{j}: {} vs {fd}", g[j]);
        }
    }
}
