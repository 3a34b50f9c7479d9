//! A step that is a lasting source's onset: one signal two families see.
//!
//! A lasting deflation begins as a jump at its nearest station, so the step scan finds it there
//! too, and the step is then significant beside the source it belongs to. A significant step is
//! taken for a significant `lasting_source`'s onset — no longer significant, and the reason
//! said — when the source ranks above it, the step's epoch lies within the source's change (its
//! scanned onset to its end, ± [`ONSET_DAYS`]) and the step's offset points within
//! [`MAX_ANGLE_DEG`] of the source's displacement at the station. A step ranked above the
//! source, at another time or across its field stays: one station's jump cannot stand for a
//! source, and a source is not dismissed for a station's jump.

use crate::analysis::{Candidate, Rejection};
use crate::gnss::Network;
use crate::model::OwnedEffect;
use magic_core::mogi;
use nalgebra::Vector3;

/// Days either side of a lasting source's change within which a step counts as its onset: the
/// spacing of the onset scan ([`super::lasting_source::SCAN_SPACING`]), which places the onset
/// to that many days.
pub const ONSET_DAYS: f64 = super::lasting_source::SCAN_SPACING as f64;
/// Largest angle (degrees) between a step's offset and the source's displacement at its station.
pub const MAX_ANGLE_DEG: f64 = 45.0;

/// What of a lasting source the rule needs: where it is, when it changes, which way.
struct Change {
    pos: [f64; 3],
    onset: f64,
    end: f64,
    sign: f64,
}

impl Change {
    fn of(c: &Candidate) -> Option<Change> {
        let Some(OwnedEffect::SecondSource {
            x_km,
            y_km,
            depth_km,
        }) = c.effect
        else {
            return None;
        };
        let day = |k: &str| {
            c.params[k]
                .as_str()
                .and_then(magic_core::time::parse_date)
                .map(|d| d as f64)
        };
        let dv = c.params["peak_dv_1e6m3"].as_f64()?;
        Some(Change {
            pos: [x_km.into(), y_km.into(), depth_km.into()],
            onset: day("onset")?,
            end: day("end")?,
            sign: if dv < 0.0 { -1.0 } else { 1.0 },
        })
    }
}

/// Why the step `(station, epoch, offset)` is the onset of `change`, if it is.
fn onset_of(
    network: &Network,
    change: &Change,
    station: usize,
    epoch: f64,
    offset: [f32; 3],
) -> Option<Rejection> {
    if epoch < change.onset - ONSET_DAYS || epoch > change.end + ONSET_DAYS {
        return None;
    }
    let here = core::slice::from_ref(network.stations.get(station)?);
    let [x, y, d] = change.pos;
    let mut at = [0.0; 3];
    mogi::field(here, &[x, y, d, change.sign], &mut at).ok()?;
    let (at, o) = (Vector3::from(at), Vector3::from(offset.map(f64::from)));
    let angle = at.angle(&o).to_degrees();
    (o.norm() > 0.0 && angle <= MAX_ANGLE_DEG).then(|| {
        Rejection::PartOf(format!(
            "the onset of the lasting_source ranked above it (offset {angle:.0}° from its \
             displacement at {}, epoch within its change ± {ONSET_DAYS:.0} days)",
            network
                .names
                .get(station)
                .map_or("its station", String::as_str)
        ))
    })
}

/// Marks each significant step that is the onset of a significant `lasting_source` ranked above
/// it (`effects` ranked, best first) as not significant, with the reason.
pub fn mark_onsets(network: &Network, effects: &mut [Candidate]) {
    for i in 0..effects.len() {
        let c = &effects[i];
        let Some(OwnedEffect::Step {
            station,
            epoch_day,
            offset_mm,
        }) = c.effect
        else {
            continue;
        };
        if !c.significant || c.rejected.is_some() {
            continue;
        }
        let why = effects[..i]
            .iter()
            .filter(|s| super::is_lasting(&s.family) && s.significant && s.rejected.is_none())
            .filter(|s| s.excess() > c.excess())
            .filter_map(Change::of)
            .find_map(|ch| onset_of(network, &ch, station.into(), epoch_day.into(), offset_mm));
        if let Some(why) = why {
            effects[i].significant = false;
            effects[i].rejected = Some(why);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    // Three stations in a row (A, B, C); the tests put a deflation under the first.
    use super::super::three_stations as network;

    fn lasting(score: f64) -> Candidate {
        let params = json!({"x_km": 1.0, "y_km": 0.0, "depth_km": 3.0,
            "onset": "2014-01-01", "start": "2013-12-01", "end": "2014-03-01", "peak_dv_1e6m3": -1.0});
        let effect = OwnedEffect::SecondSource {
            x_km: 1.0,
            y_km: 0.0,
            depth_km: 3.0,
        };
        significant("lasting_source", score, params, effect)
    }

    fn step(score: f64, station: u16, date: &str, offset_mm: [f32; 3]) -> Candidate {
        let epoch_day = magic_core::time::parse_date(date).unwrap() as f32;
        let effect = OwnedEffect::Step {
            station,
            epoch_day,
            offset_mm,
        };
        significant("step", score, json!({}), effect)
    }

    fn significant(
        family: &str,
        score: f64,
        params: serde_json::Value,
        e: OwnedEffect,
    ) -> Candidate {
        let noise = vec![0.001, 0.002, 0.0015, 0.001, 0.002];
        let c = Candidate::from_scores(family, score, noise, 0.95, params, Some(e));
        assert!(c.significant);
        c
    }

    /// Station A, 1 km west of a deflation 3 km deep, moves east (towards it) and down.
    const TOWARDS: [f32; 3] = [2.0, 0.0, -5.0];

    #[test]
    fn a_step_along_the_source_at_its_onset_is_the_onset() {
        let mut e = vec![lasting(0.05), step(0.03, 0, "2013-12-20", TOWARDS)];
        mark_onsets(&network(), &mut e);
        assert!(!e[1].significant, "{:?}", e[1]);
        let why = &e[1].rejected;
        assert!(
            matches!(why, Some(Rejection::PartOf(w)) if w.contains("onset")),
            "{why:?}"
        );
        assert!(e[0].significant && e[0].rejected.is_none());
    }

    #[test]
    fn a_step_ranked_above_elsewhere_or_across_stays() {
        let cases = [
            // Ranked above the source.
            vec![step(0.06, 0, "2014-02-01", TOWARDS), lasting(0.05)],
            // More than ONSET_DAYS before the change, or after it.
            vec![lasting(0.05), step(0.03, 0, "2013-11-15", TOWARDS)],
            vec![lasting(0.05), step(0.03, 0, "2014-04-15", TOWARDS)],
            // Across the source's displacement at the station, or against it.
            vec![lasting(0.05), step(0.03, 0, "2014-02-01", [5.0, 0.0, 2.0])],
            vec![lasting(0.05), step(0.03, 0, "2014-02-01", [-2.0, 0.0, 5.0])],
        ];
        for mut e in cases {
            let before: Vec<bool> = e.iter().map(|c| c.significant).collect();
            mark_onsets(&network(), &mut e);
            let after: Vec<bool> = e.iter().map(|c| c.significant).collect();
            assert_eq!(before, after, "{e:?}");
            assert!(e.iter().all(|c| c.rejected.is_none()));
        }
    }
}
