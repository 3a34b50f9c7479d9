//! Where the synthetic data are made: the station network, the main source under it and the
//! source bounds the encoder is given. Akutan (the paper's release) by default; any network from
//! a `stations.json` (`magic synth --stations FILE`), so that the recovery check is not tuned to
//! one geometry either.

use super::source::SOURCE;
use crate::gnss::{Network, SourceBounds};
use anyhow::{bail, Result};
use std::path::Path;

/// The fewest stations a synthetic network may have: the analysis holds stations out in turn
/// and a point source has four parameters.
pub const MIN_STATIONS: usize = 5;

/// Depth (km) of the main source under another network's stations (Akutan's, [`SOURCE`]).
pub const MAIN_DEPTH_KM: f64 = SOURCE[2];

/// The network, the main source and the bounds of a synthetic dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct Site {
    /// The stations.
    pub network: Network,
    /// The main source's position and depth (km).
    pub source: [f64; 3],
    /// The box (x0, x1, y0, y1; km) over which a second source `apart` from the main one is
    /// drawn (the scenario `second_source`).
    pub apart_box: [f64; 4],
    /// The source bounds the dataset carries (`bounds.json` unless the paper's).
    pub bounds: SourceBounds,
}

impl Site {
    /// The paper's Akutan network, its source 0.3 km east and 0.2 km north of the origin and
    /// 7 km deep, the bounds of the paper's Table 2.
    pub fn akutan() -> Site {
        Site {
            network: Network::akutan(),
            source: SOURCE,
            apart_box: [-8.0, 12.0, -5.0, 7.0],
            bounds: SourceBounds::paper(),
        }
    }

    /// Another network: the main source under its stations' centroid, [`MAIN_DEPTH_KM`] deep; a
    /// second source apart drawn over the stations' box; the bounds over that box, 2–20 km deep
    /// (as the paper's Table 2 is for Akutan; [`Site::with_bounds`] for others).
    ///
    /// ```
    /// use magic_train::gnss::synth::Site;
    /// use magic_train::gnss::Network;
    /// let mut network = Network::akutan();
    /// network.stations.iter_mut().for_each(|s| s.x_km += 30.0);
    /// let site = Site::on(network).unwrap();
    /// assert!((site.source[0] - 30.0).abs() < 0.1 && site.source[1].abs() < 0.1);
    /// assert_eq!(site.bounds.0[2], [2.0, 20.0]);
    /// ```
    pub fn on(network: Network) -> Result<Site> {
        let n = network.len();
        if n < MIN_STATIONS {
            bail!("a synthetic network needs at least {MIN_STATIONS} stations (found {n})");
        }
        let bounds = SourceBounds::from_network(&network, 0.0, [2.0, 20.0])?;
        let [x, y] = [bounds.0[0], bounds.0[1]];
        let mean = |f: &dyn Fn(&magic_core::mogi::Station) -> f64| {
            network.stations.iter().map(f).sum::<f64>() / n as f64
        };
        let source = [mean(&|s| s.x_km), mean(&|s| s.y_km), MAIN_DEPTH_KM];
        Ok(Site {
            apart_box: [x[0], x[1], y[0], y[1]],
            source,
            bounds,
            network,
        })
    }

    /// The same with `bounds` (a prepared dataset's): an error when the main source lies
    /// outside them.
    pub fn with_bounds(self, bounds: SourceBounds) -> Result<Site> {
        for (k, name) in ["x_km", "y_km", "depth_km"].iter().enumerate() {
            let ([lo, hi], v) = (bounds.0[k], self.source[k]);
            if !(lo..=hi).contains(&v) {
                bail!("the main source's {name} {v:.3} lies outside the bounds [{lo}, {hi}]");
            }
        }
        Ok(Site { bounds, ..self })
    }

    /// [`Site::on`] the network of a `stations.json`, with the bounds of a `bounds.json` beside
    /// it where there is one (a dataset `magic prepare` wrote), so that the check runs with the
    /// bounds the user's training has.
    pub fn read(path: &Path) -> Result<Site> {
        let site = Site::on(Network::read_json(path, None)?)
            .map_err(|e| e.context(format!("{}", path.display())))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        match SourceBounds::read_dir(dir)? {
            Some(b) => site.with_bounds(b).map_err(|e| {
                e.context(format!(
                    "{}",
                    dir.join(crate::gnss::bounds::BOUNDS_FILE).display()
                ))
            }),
            None => Ok(site),
        }
    }
}

impl Default for Site {
    fn default() -> Self {
        Site::akutan()
    }
}
