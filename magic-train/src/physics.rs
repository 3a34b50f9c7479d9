//! The bridge between magic-core's forward models and candle's autograd.
//!
//! [`PhysicsOp`] is a candle custom op whose forward pass evaluates a core forward model row by
//! row (rayon over the batch) and whose backward pass multiplies the incoming gradient by the
//! model's exact Jacobian (forward-mode duals in the core). There is no second implementation of
//! the physics in the trainer.
//!
//! The Jacobian computation yields the values too, so a training step that evaluates the values
//! in the forward pass and the Jacobian in the backward pass computes the values twice. A model
//! that offers a [`JacobianReuse`] lets the forward pass compute values and Jacobians together
//! while training and the backward pass reuse them (see there); the op cannot know in its forward
//! pass whether a backward pass will follow, so the choice adapts to what the last passes did.

use candle_core::{CpuStorage, CustomOp1, Layout, Shape, Tensor};
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// A forward model the trainer can differentiate through.
pub trait Physics: Send + Sync {
    /// Number of physical variables.
    fn n_params(&self) -> usize;
    /// Number of outputs.
    fn n_obs(&self) -> usize;
    /// Values for an observation on day `t` (NaN if unknown): `out` has `n_obs` entries.
    fn forward(&self, p: &[f64], t: f64, out: &mut [f64]) -> Result<(), magic_core::Error>;
    /// Values and Jacobian (`jac` row-major, `n_obs × n_params`).
    fn jacobian(
        &self,
        p: &[f64],
        t: f64,
        out: &mut [f64],
        jac: &mut [f64],
    ) -> Result<(), magic_core::Error>;
    /// F's dated terms on day `t` (`magic_core::effects::Effect::is_dated`: steps and drifts;
    /// `out` overwritten; zero by default): a variant-C model corrects F without them and adds
    /// them after C
    /// (`magic_core::invert::model_correction`).
    fn dated(&self, t: f64, out: &mut [f64]) -> Result<(), magic_core::Error> {
        let _ = t;
        out.fill(0.0);
        Ok(())
    }
    /// Whether F holds dated terms at all ([`Physics::dated`] nonzero on some day); `false` (the
    /// default) lets a caller skip evaluating them.
    fn has_dated(&self) -> bool {
        false
    }
    /// Where [`PhysicsOp`] keeps Jacobians its forward pass computed for its backward pass; `None`
    /// (the default): the forward pass computes values only, the backward pass the Jacobian.
    fn jacobian_reuse(&self) -> Option<&JacobianReuse> {
        None
    }
}

/// Jacobians computed in [`PhysicsOp`]'s forward pass for its backward pass, for a model whose
/// Jacobian costs a few times its values (INFORM: about 3.5×), so that a training step computes
/// the values once instead of twice.
///
/// The forward pass computes Jacobians after a backward pass found none to reuse (training), and
/// stops after a forward pass whose Jacobians were not used (validation, evaluation): a training
/// epoch then wastes Jacobians on one validation batch, and evaluation runs at the cost of the
/// values alone. Jacobians are matched to their backward pass by op and by input.
#[derive(Debug, Default)]
pub struct JacobianReuse {
    /// Whether the next forward pass computes Jacobians.
    eager: AtomicBool,
    /// Jacobians of forward passes whose backward pass has not run yet.
    pending: Mutex<Vec<Pending>>,
}

/// The Jacobians of one forward pass.
#[derive(Debug)]
struct Pending {
    /// The op (its address, stable while candle holds it).
    op: usize,
    /// The op's input (rows of variables and day number).
    input: Vec<f64>,
    /// Jacobians row after row, `n_obs × n_params` each.
    jac: Vec<f64>,
}

impl Clone for JacobianReuse {
    /// A fresh, empty reuse (nothing pending, values only until a backward pass).
    fn clone(&self) -> Self {
        JacobianReuse::default()
    }
}

impl JacobianReuse {
    /// At the start of a forward pass: whether to compute Jacobians. Jacobians still pending
    /// here were not used: they are dropped, and the next passes compute values only.
    fn begin_forward(&self) -> bool {
        let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
        if !pending.is_empty() {
            pending.clear();
            self.eager.store(false, Ordering::Relaxed);
        }
        self.eager.load(Ordering::Relaxed)
    }

    fn store(&self, p: Pending) {
        self.pending
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(p);
    }

    /// The Jacobians op `op` computed for `input`, if any; when there are none the backward
    /// pass computes them, and the next forward passes compute them ahead.
    fn take(&self, op: usize, input: &[f64]) -> Option<Vec<f64>> {
        let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
        // Bit for bit: unknown day numbers are NaN.
        let same = |a: &[f64]| {
            a.len() == input.len() && a.iter().zip(input).all(|(x, y)| x.to_bits() == y.to_bits())
        };
        let found = pending.iter().position(|p| p.op == op && same(&p.input));
        match found {
            Some(i) => Some(pending.swap_remove(i).jac),
            None => {
                self.eager.store(true, Ordering::Relaxed);
                None
            }
        }
    }
}

/// The candle op applying a [`Physics`] to a `(batch, n_params + 1)` tensor: the variables, then
/// the day number of each row (NaN if unknown; it receives no gradient).
#[derive(Clone)]
pub struct PhysicsOp(pub Arc<dyn Physics>);

fn core_err(e: magic_core::Error) -> candle_core::Error {
    candle_core::Error::Msg(format!("forward model: {e}"))
}

impl PhysicsOp {
    /// This op's identity while candle holds it (for [`JacobianReuse`]).
    fn id(&self) -> usize {
        self as *const Self as usize
    }
}

impl CustomOp1 for PhysicsOp {
    fn name(&self) -> &'static str {
        "physics"
    }

    fn cpu_fwd(
        &self,
        storage: &CpuStorage,
        layout: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (b, p1) = layout.shape().dims2()?;
        let p = p1 - 1;
        let (start, end) = layout
            .contiguous_offsets()
            .ok_or_else(|| candle_core::Error::Msg("physics op needs a contiguous input".into()))?;
        let input: Vec<f64> = match storage {
            CpuStorage::F32(v) => v[start..end].iter().map(|x| *x as f64).collect(),
            CpuStorage::F64(v) => v[start..end].to_vec(),
            _ => {
                return Err(candle_core::Error::Msg(
                    "physics op takes f32 or f64".into(),
                ))
            }
        };
        let n = self.0.n_obs();
        let mut out = vec![0f64; b * n];
        match self.0.jacobian_reuse().filter(|r| r.begin_forward()) {
            Some(reuse) => {
                let mut jac = vec![0f64; b * n * p];
                out.par_chunks_mut(n)
                    .zip(jac.par_chunks_mut(n * p))
                    .zip(input.par_chunks(p1))
                    .try_for_each(|((o, j), z)| self.0.jacobian(&z[..p], z[p], o, j))
                    .map_err(core_err)?;
                reuse.store(Pending {
                    op: self.id(),
                    input,
                    jac,
                });
            }
            None => out
                .par_chunks_mut(n)
                .zip(input.par_chunks(p1))
                .try_for_each(|(o, z)| self.0.forward(&z[..p], z[p], o))
                .map_err(core_err)?,
        }
        let storage = match storage {
            CpuStorage::F64(_) => CpuStorage::F64(out),
            _ => CpuStorage::F32(out.into_iter().map(|x| x as f32).collect()),
        };
        Ok((storage, Shape::from((b, n))))
    }

    fn bwd(
        &self,
        arg: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<Option<Tensor>> {
        let (b, p1) = arg.dims2()?;
        let p = p1 - 1;
        let n = self.0.n_obs();
        let z = arg
            .to_dtype(candle_core::DType::F64)?
            .flatten_all()?
            .to_vec1::<f64>()?;
        let g = grad
            .to_dtype(candle_core::DType::F64)?
            .flatten_all()?
            .to_vec1::<f64>()?;
        let cached = self.0.jacobian_reuse().and_then(|r| r.take(self.id(), &z));
        let mut gz = vec![0f64; b * p1];
        gz.par_chunks_mut(p1)
            .enumerate()
            .try_for_each(|(i, gi)| {
                let jac: Cow<[f64]> = match &cached {
                    Some(all) => Cow::Borrowed(&all[i * n * p..(i + 1) * n * p]),
                    None => {
                        let mut out = vec![0f64; n];
                        let mut jac = vec![0f64; n * p];
                        self.0.jacobian(
                            &z[i * p1..i * p1 + p],
                            z[i * p1 + p],
                            &mut out,
                            &mut jac,
                        )?;
                        Cow::Owned(jac)
                    }
                };
                for c in 0..n {
                    let gc = g[i * n + c];
                    for j in 0..p {
                        gi[j] += gc * jac[c * p + j];
                    }
                }
                Ok(())
            })
            .map_err(core_err)?;
        let t = Tensor::from_vec(gz, (b, p1), arg.device())?.to_dtype(arg.dtype())?;
        Ok(Some(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::MogiPhysics;
    use candle_core::{Device, Var};
    use magic_core::mogi::Station;

    #[test]
    fn gradient_through_op_matches_finite_differences() {
        let phys: Arc<dyn Physics> = Arc::new(MogiPhysics::new(
            vec![
                Station {
                    x_km: -4.0,
                    y_km: 6.0,
                    z_km: 0.3,
                },
                Station {
                    x_km: 10.0,
                    y_km: 0.5,
                    z_km: 0.4,
                },
            ],
            vec![],
        ));
        let dev = Device::Cpu;
        let z0 = [1.0f64, -0.5, 6.0, 2.0];
        let z = Var::from_vec(vec![1.0, -0.5, 6.0, 2.0, f64::NAN], (1, 5), &dev).unwrap();
        let y = z.as_tensor().apply_op1(PhysicsOp(phys.clone())).unwrap();
        let loss = y.sqr().unwrap().sum_all().unwrap();
        let grads = loss.backward().unwrap();
        let g = grads
            .get(&z)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let f = |p: &[f64]| {
            let mut o = vec![0.0; 6];
            phys.forward(p, f64::NAN, &mut o).unwrap();
            o.iter().map(|v| v * v).sum::<f64>()
        };
        for j in 0..4 {
            let h = 1e-6;
            let (mut a, mut b) = (z0, z0);
            a[j] += h;
            b[j] -= h;
            let fd = (f(&a) - f(&b)) / (2.0 * h);
            assert!(
                (g[j] - fd).abs() <= 1e-6 * fd.abs().max(1.0),
                "{j}: {} vs {fd}",
                g[j]
            );
        }
    }

    /// `y = (p0·p1, p0 + p1)`, counting how many rows each method evaluated.
    #[derive(Default)]
    struct Counting {
        forwards: std::sync::atomic::AtomicUsize,
        jacobians: std::sync::atomic::AtomicUsize,
        reuse: JacobianReuse,
    }

    impl Physics for Counting {
        fn n_params(&self) -> usize {
            2
        }
        fn n_obs(&self) -> usize {
            2
        }
        fn forward(&self, p: &[f64], _t: f64, out: &mut [f64]) -> Result<(), magic_core::Error> {
            self.forwards.fetch_add(1, Ordering::Relaxed);
            out.copy_from_slice(&[p[0] * p[1], p[0] + p[1]]);
            Ok(())
        }
        fn jacobian(
            &self,
            p: &[f64],
            t: f64,
            out: &mut [f64],
            jac: &mut [f64],
        ) -> Result<(), magic_core::Error> {
            self.jacobians.fetch_add(1, Ordering::Relaxed);
            self.forwards.fetch_sub(1, Ordering::Relaxed);
            self.forward(p, t, out)?;
            jac.copy_from_slice(&[p[1], p[0], 1.0, 1.0]);
            Ok(())
        }
        fn jacobian_reuse(&self) -> Option<&JacobianReuse> {
            Some(&self.reuse)
        }
    }

    #[test]
    fn training_steps_reuse_the_forward_jacobians() {
        let phys = Arc::new(Counting::default());
        let dyn_phys: Arc<dyn Physics> = phys.clone();
        let dev = Device::Cpu;
        let z = Var::from_vec(vec![2.0, 3.0, f64::NAN, -1.0, 0.5, f64::NAN], (2, 3), &dev).unwrap();
        // d/dz Σ y² = 2·y·J: row (2, 3): y = (6, 5) -> (2·6·3 + 2·5, 2·6·2 + 2·5) = (46, 34).
        let step = || {
            let y = z
                .as_tensor()
                .apply_op1(PhysicsOp(dyn_phys.clone()))
                .unwrap();
            let loss = y.sqr().unwrap().sum_all().unwrap();
            let g = loss.backward().unwrap();
            let g = g
                .get(&z)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1::<f64>()
                .unwrap();
            assert_eq!(&g[..2], &[46.0, 34.0]);
        };
        let counts = || {
            (
                phys.forwards.load(Ordering::Relaxed),
                phys.jacobians.load(Ordering::Relaxed),
            )
        };
        // The first step: values in the forward pass, Jacobians in the backward pass.
        step();
        assert_eq!(counts(), (2, 2));
        // Later steps compute each row once, Jacobian and values together.
        step();
        step();
        assert_eq!(counts(), (2, 6));
        // A forward pass without a backward pass (validation) wastes its Jacobians once...
        z.as_tensor()
            .apply_op1(PhysicsOp(dyn_phys.clone()))
            .unwrap();
        assert_eq!(counts(), (2, 8));
        // ...after which forward passes compute values only.
        let y = z
            .as_tensor()
            .apply_op1(PhysicsOp(dyn_phys.clone()))
            .unwrap();
        assert_eq!(counts(), (4, 8));
        assert_eq!(y.to_vec2::<f64>().unwrap()[1], vec![-0.5, -0.5]);
        // Training again: the backward pass finds nothing cached, and the next steps reuse.
        step();
        step();
        assert_eq!(counts(), (6, 12));
    }
}
