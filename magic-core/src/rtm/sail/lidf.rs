//! Leaf inclination distributions (LIDF) for 4SAIL: rows of a beta-distribution table or
//! Campbell's ellipsoidal distribution, as weights at bin-centre angles.

use crate::real::Real;
use crate::Error;
use core::f64::consts::PI;

/// Leaf inclination bin centres (degrees) of the reference's 13-bin discretisation.
pub const LITAB_DEG: [f64; 13] = [
    5.0, 15.0, 25.0, 35.0, 45.0, 55.0, 65.0, 75.0, 81.0, 83.0, 85.0, 87.0, 89.0,
];

/// Bin edges (degrees) of the 13-bin discretisation (10° bins to 80°, then 2° bins).
const EDGES13_DEG: [f64; 14] = [
    0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 82.0, 84.0, 86.0, 88.0, 90.0,
];

/// Largest number of inclination bins a [`Lidf`] holds.
pub const MAX_BINS: usize = 18;

/// How a Campbell (ellipsoidal) distribution is discretised.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CampbellBins {
    /// The reference's 13 bins, centres [`LITAB_DEG`] (as `lidf_tables.csv`).
    Reference13,
    /// 18 bins of 5°, centres 2.5°, 7.5°, …, 87.5° (as the `prosail` package).
    Uniform18,
}

/// A leaf inclination distribution: weights (summing to 1) at bin-centre angles.
#[derive(Clone, Copy, Debug)]
pub struct Lidf<R> {
    n: usize,
    angle_deg: [f64; MAX_BINS],
    weight: [R; MAX_BINS],
}

impl<R: Real> Lidf<R> {
    /// Row `row` of a beta-distribution table with 13 inclination bins ([`LITAB_DEG`]), stored
    /// angle-major as in `lidf_tables.csv`: the weight of bin `i` in distribution `row` is
    /// `table[i * n_rows + row]` with `n_rows = table.len() / 13`.
    pub fn from_beta_table(table: &[f64], row: usize) -> Result<Self, Error> {
        if table.is_empty() || table.len() / LITAB_DEG.len() * LITAB_DEG.len() != table.len() {
            return Err(Error::SizeMismatch {
                what: "lidf beta table (13 angles x rows)",
                expected: LITAB_DEG.len() * (table.len() / LITAB_DEG.len()).max(1),
                found: table.len(),
            });
        }
        let n_rows = table.len() / LITAB_DEG.len();
        if row >= n_rows {
            return Err(Error::OutOfRange {
                what: "LIDF beta table row",
            });
        }
        let mut l = Lidf {
            n: LITAB_DEG.len(),
            angle_deg: [0.0; MAX_BINS],
            weight: [R::zero(); MAX_BINS],
        };
        for (i, &a) in LITAB_DEG.iter().enumerate() {
            let w = table[i * n_rows + row];
            if !w.is_finite() {
                return Err(Error::NonFinite {
                    what: "lidf beta table",
                    index: i * n_rows + row,
                });
            }
            l.angle_deg[i] = a;
            l.weight[i] = R::c(w);
        }
        Ok(l)
    }

    /// Campbell's ellipsoidal distribution for mean leaf angle `ala` (degrees, 0 < ala < 90),
    /// integrated over each bin analytically (Campbell 1990) and normalised to sum 1.
    pub fn campbell(ala: R, bins: CampbellBins) -> Result<Self, Error> {
        let a = ala.value();
        if !a.is_finite() {
            return Err(Error::NonFinite {
                what: "mean leaf angle",
                index: 0,
            });
        }
        if !(a > 0.0 && a < 90.0) {
            return Err(Error::OutOfRange {
                what: "mean leaf angle (0..90 degrees)",
            });
        }
        let excent = (R::c(-1.6184e-5) * ala * ala * ala + R::c(2.1145e-3) * ala * ala
            - R::c(1.2390e-1) * ala
            + R::c(3.2491))
        .exp();
        let ev = excent.value();
        let mut l = Lidf {
            n: 0,
            angle_deg: [0.0; MAX_BINS],
            weight: [R::zero(); MAX_BINS],
        };
        let (n, step) = match bins {
            CampbellBins::Reference13 => (13, 0.0),
            CampbellBins::Uniform18 => (18, 5.0),
        };
        l.n = n;
        let e2 = excent * excent;
        let one = R::one();
        // alph = e / sqrt(|1 − e²|) (unused when e == 1)
        let alph = if ev == 1.0 {
            one
        } else {
            excent / (one - e2).abs().sqrt()
        };
        let alph2 = alph * alph;
        let prim = |tl_deg: f64| -> R {
            let t = libm::tan(tl_deg * PI / 180.0);
            let x = excent / (one + e2 * R::c(t * t)).sqrt();
            if ev > 1.0 {
                let s = (alph2 + x * x).sqrt();
                x * s + alph2 * (x + s).ln()
            } else {
                let s = (alph2 - x * x).sqrt();
                x * s + alph2 * (x / alph).asin()
            }
        };
        let mut sum = R::zero();
        for i in 0..n {
            let (lo, hi, centre) = match bins {
                CampbellBins::Reference13 => (EDGES13_DEG[i], EDGES13_DEG[i + 1], LITAB_DEG[i]),
                CampbellBins::Uniform18 => (
                    i as f64 * step,
                    (i + 1) as f64 * step,
                    (i as f64 + 0.5) * step,
                ),
            };
            let f = if ev == 1.0 {
                R::c(libm::fabs(
                    libm::cos(lo * PI / 180.0) - libm::cos(hi * PI / 180.0),
                ))
            } else {
                (prim(hi) - prim(lo)).abs()
            };
            l.angle_deg[i] = centre;
            l.weight[i] = f;
            sum += f;
        }
        for w in l.weight[..n].iter_mut() {
            *w /= sum;
        }
        Ok(l)
    }

    /// Number of bins.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there is no bin (never true for a constructed distribution).
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Bin weights.
    pub fn weights(&self) -> &[R] {
        &self.weight[..self.n]
    }

    /// Bin-centre inclination angles (degrees).
    pub fn angles_deg(&self) -> &[f64] {
        &self.angle_deg[..self.n]
    }
}
