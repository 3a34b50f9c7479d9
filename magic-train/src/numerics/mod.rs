//! Small numerical helpers the analysis and the reports share: order statistics, spread, rank
//! correlation. (Dense linear algebra comes from nalgebra, FFTs from rustfft.)

pub mod stats;

pub use stats::{mean_std, mean_std_text, median, quantile, sd, spearman};
