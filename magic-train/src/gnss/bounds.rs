//! The bounds of the Mogi source's variables (x, y, depth in km, ΔV in 10⁶ m³): the encoder's
//! sigmoid head is mapped onto them, and the model file carries them. The paper's Table 2 gives
//! them for Akutan (x and y span the station network's box); for another network they are
//! derived the same way from its stations ([`SourceBounds::from_network`]) and kept beside the
//! data as `bounds.json` (`{"x_km": [min, max], "y_km": …, "depth_km": …, "dv_1e6m3": …}`).

use super::Network;
use anyhow::{bail, Context, Result};
use magic_core::mogi::{PAPER_BOUNDS, PARAM_NAMES};
use serde_json::json;
use std::path::Path;

/// The file name beside the data.
pub const BOUNDS_FILE: &str = "bounds.json";

/// Bounds `[min, max]` of x, y, depth (km) and ΔV (10⁶ m³), in [`PARAM_NAMES`] order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SourceBounds(pub [[f64; 2]; 4]);

impl Default for SourceBounds {
    fn default() -> Self {
        SourceBounds::paper()
    }
}

impl SourceBounds {
    /// The paper's Table 2 (Akutan).
    pub fn paper() -> SourceBounds {
        SourceBounds(PAPER_BOUNDS)
    }

    /// x and y over the stations' box widened by `margin_km` on every side, the depth range
    /// given, ΔV as in the paper (±10·10⁶ m³).
    ///
    /// ```
    /// use magic_train::gnss::{bounds::SourceBounds, Network};
    /// let b = SourceBounds::from_network(&Network::akutan(), 0.0, [2.0, 20.0]).unwrap();
    /// // The paper's Table 2 is the Akutan box, rounded to 10 m.
    /// for (got, paper) in b.0.iter().zip(SourceBounds::paper().0) {
    ///     assert!((got[0] - paper[0]).abs() < 0.01 && (got[1] - paper[1]).abs() < 0.01);
    /// }
    /// ```
    pub fn from_network(
        network: &Network,
        margin_km: f64,
        depth_km: [f64; 2],
    ) -> Result<SourceBounds> {
        if network.is_empty() {
            bail!("no stations to derive source bounds from");
        }
        if !(margin_km.is_finite() && margin_km >= 0.0) {
            bail!("the margin must be a non-negative distance (found {margin_km} km)");
        }
        let span = |f: &dyn Fn(&magic_core::mogi::Station) -> f64| {
            let v = network.stations.iter().map(f);
            let lo = v.clone().fold(f64::INFINITY, f64::min);
            let hi = v.fold(f64::NEG_INFINITY, f64::max);
            [lo - margin_km, hi + margin_km]
        };
        let mut x = span(&|s| s.x_km);
        let mut y = span(&|s| s.y_km);
        // A network on a line (or a single station) still needs a range across it.
        for r in [&mut x, &mut y] {
            if r[1] - r[0] < 1.0 {
                let mid = 0.5 * (r[0] + r[1]);
                *r = [mid - 0.5, mid + 0.5];
            }
        }
        let b = SourceBounds([x, y, depth_km, PAPER_BOUNDS[3]]);
        b.check()?;
        Ok(b)
    }

    /// Checks every range: finite, min < max, depth above zero.
    pub fn check(&self) -> Result<()> {
        for (name, [lo, hi]) in PARAM_NAMES.iter().zip(self.0) {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                bail!("bounds of {name}: expected finite min < max, found [{lo}, {hi}]");
            }
        }
        if self.0[2][0] <= 0.0 {
            bail!(
                "bounds of depth_km: the shallowest depth must be below the surface (above 0 km), found {}",
                self.0[2][0]
            );
        }
        Ok(())
    }

    /// `bounds.json` in `dir`, if there is one.
    pub fn read_dir(dir: &Path) -> Result<Option<SourceBounds>> {
        let path = dir.join(BOUNDS_FILE);
        if !path.exists() {
            return Ok(None);
        }
        SourceBounds::read(&path).map(Some)
    }

    /// Reads a `bounds.json`.
    pub fn read(path: &Path) -> Result<SourceBounds> {
        let shown = path.display();
        let text =
            std::fs::read_to_string(path).with_context(|| format!("{shown}: cannot read"))?;
        let v: serde_json::Value =
            serde_json::from_str(&text).with_context(|| format!("{shown}: not valid JSON"))?;
        let mut b = [[0.0; 2]; 4];
        for (k, name) in PARAM_NAMES.iter().enumerate() {
            let pair = v
                .get(name)
                .and_then(|p| p.as_array())
                .filter(|p| p.len() == 2)
                .and_then(|p| Some([p[0].as_f64()?, p[1].as_f64()?]))
                .with_context(|| {
                    format!("{shown}: `{name}` missing or not a pair of numbers [min, max]")
                })?;
            b[k] = pair;
        }
        let b = SourceBounds(b);
        b.check().with_context(|| format!("{shown}"))?;
        Ok(b)
    }

    /// Writes `bounds.json` into `dir`.
    pub fn write_dir(&self, dir: &Path) -> Result<()> {
        let mut m = serde_json::Map::new();
        for (name, b) in PARAM_NAMES.iter().zip(self.0) {
            m.insert(name.to_string(), json!(b));
        }
        let path = dir.join(BOUNDS_FILE);
        std::fs::write(&path, serde_json::to_string_pretty(&m)?)
            .with_context(|| format!("{}: cannot write", path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derived_bounds_round_trip_and_checks() {
        let dir = std::env::temp_dir().join(format!("magic-bounds-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert_eq!(SourceBounds::read_dir(&dir).unwrap(), None);
        let b = SourceBounds::from_network(&Network::akutan(), 2.0, [1.0, 12.0]).unwrap();
        assert!((b.0[0][0] - (-11.329)).abs() < 1e-3 && (b.0[1][1] - 9.627).abs() < 1e-3);
        assert_eq!(b.0[2], [1.0, 12.0]);
        b.write_dir(&dir).unwrap();
        assert_eq!(SourceBounds::read_dir(&dir).unwrap(), Some(b));
        std::fs::write(
            dir.join(BOUNDS_FILE),
            r#"{"x_km": [1, 0], "y_km": [0, 1], "depth_km": [1, 2], "dv_1e6m3": [-1, 1]}"#,
        )
        .unwrap();
        let e = SourceBounds::read_dir(&dir).unwrap_err();
        assert!(format!("{e:#}").contains("x_km"), "{e:#}");
        std::fs::write(dir.join(BOUNDS_FILE), r#"{"x_km": [0, 1]}"#).unwrap();
        let e = SourceBounds::read_dir(&dir).unwrap_err();
        assert!(format!("{e:#}").contains("y_km"), "{e:#}");
        assert!(SourceBounds::from_network(&Network::akutan(), 0.0, [0.0, 5.0]).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
