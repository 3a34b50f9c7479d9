//! Small numerical helpers the analysis and the reports share: order statistics, spread, rank
//! correlation, and the white + AR(1) noise model of the step scan. (Dense linear algebra comes
//! from nalgebra, FFTs from rustfft.)

pub mod ar1_white;
pub mod stats;

pub use ar1_white::{Ar1White, StepScan};
pub use stats::{
    binomial_cdf, clopper_pearson, mean_std, mean_std_text, median, quantile, sd, spearman,
    ONE_SIGMA,
};
