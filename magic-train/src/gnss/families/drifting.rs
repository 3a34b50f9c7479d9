//! A step at a drifting station: one signal two families see.
//!
//! A linear drift in slow noise peaks the step scan at its station (its scan statistic stands
//! out of surrogates, which turn the trend into a stationary wander), though such a step's
//! held-out score stays below chance: a level that wanders predicts held-out days no better than
//! the surrogates' best steps. A step significant by its statistic alone (score below chance,
//! [`crate::analysis::Family::statistic`]) is taken for a significant `drift` ranked above it at
//! the same station — no longer significant, and the reason said. A step whose score is above
//! chance stays (a real step mid-record draws a drift at its station too). The loop declares the
//! drift first and judges the station's steps again on what it leaves.

use crate::analysis::{Candidate, Rejection};
use crate::gnss::Network;
use crate::model::OwnedEffect;

/// Whether the drift `rate` (mm/yr per channel, component-major over `ns` stations) moves
/// `station`.
fn drifts(rate: &[f32], ns: usize, station: usize) -> bool {
    (0..3).any(|k| rate.get(k * ns + station).is_some_and(|r| *r != 0.0))
}

/// Marks each step significant with a score below chance at a station a significant `drift`
/// ranked above it moves (`effects` ranked, best first) as not significant, with the reason.
pub fn mark_drifting(network: &Network, effects: &mut [Candidate]) {
    let ns = network.stations.len();
    for i in 0..effects.len() {
        let c = &effects[i];
        let Some(OwnedEffect::Step { station, .. }) = c.effect else {
            continue;
        };
        if !c.significant || c.rejected.is_some() || c.excess() > 0.0 {
            continue;
        }
        let drifting = effects[..i]
            .iter()
            .filter(|d| d.family == "drift" && d.significant && d.rejected.is_none())
            .filter(|d| d.excess() > c.excess())
            .any(|d| match &d.effect {
                Some(OwnedEffect::Drift { rate, .. }) => drifts(rate, ns, station.into()),
                _ => false,
            });
        if drifting {
            let name = network
                .names
                .get(usize::from(station))
                .map_or("its station", String::as_str);
            effects[i].significant = false;
            effects[i].rejected = Some(Rejection::PartOf(format!(
                "the drift ranked above it at {name} (a trend peaks the step scan)"
            )));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    use super::super::three_stations as network;

    /// A candidate scoring `score` against the same surrogate scores (chance about 0.002).
    fn candidate(family: &str, score: f64, e: OwnedEffect) -> Candidate {
        let noise = vec![0.001, 0.002, 0.0015, 0.001, 0.002];
        Candidate::from_scores(family, score, noise, 0.95, json!({}), Some(e))
    }

    /// A drift at station B (its up component only).
    fn drift(score: f64) -> Candidate {
        let mut rate = vec![0.0; 9];
        rate[2 * 3 + 1] = 4.0;
        let c = candidate("drift", score, OwnedEffect::Drift { t0_day: 0.0, rate });
        assert!(c.significant);
        c
    }

    /// A step at `station` scoring `score`; significant by its statistic when below chance.
    fn step(score: f64, station: u16) -> Candidate {
        let effect = OwnedEffect::Step {
            station,
            epoch_day: 15_000.0,
            offset_mm: [1.0, 1.0, 5.0],
        };
        let mut c = candidate("step", score, effect);
        c.significant = true;
        c
    }

    #[test]
    fn a_step_below_chance_at_a_drifting_station_is_the_drift() {
        let mut e = vec![drift(0.2), step(0.0015, 1)];
        assert!(e[1].excess() < 0.0);
        mark_drifting(&network(), &mut e);
        assert!(!e[1].significant, "{:?}", e[1]);
        assert!(
            matches!(&e[1].rejected, Some(Rejection::PartOf(w)) if w.contains("drift") && w.contains('B')),
            "{:?}",
            e[1].rejected
        );
        assert!(e[0].significant && e[0].rejected.is_none());
    }

    #[test]
    fn a_step_above_chance_elsewhere_or_ranked_above_stays() {
        for mut e in [
            vec![drift(0.2), step(0.03, 1)],
            vec![drift(0.2), step(0.0015, 0)],
            vec![drift(0.2), step(0.0015, 2)],
            vec![step(0.3, 1), drift(0.2)],
        ] {
            mark_drifting(&network(), &mut e);
            assert!(
                e.iter().all(|c| c.significant && c.rejected.is_none()),
                "{e:?}"
            );
        }
    }
}
