//! The GNSS effect families, one type per file; [`all`] registers them (one line each).
//!
//! Two kinds share their machinery: *latent* families ([`latent`]: a pattern with a daily
//! amplitude the encoder would infer, scored by leave-one-station-out prediction on neighbouring
//! days) and *dated* families ([`dated`]: functions of the date with fitted constants, scored by
//! cross-validation over blocks of days and on the held-out splits).

pub mod common_mode;
pub mod dated;
pub mod drift;
pub mod drifting;
pub mod elevation;
pub mod held_station;
pub mod lasting_source;
pub mod latent;
pub mod matched;
pub mod onset;
pub mod seasonal;
pub mod second_source;
pub mod step;

use crate::analysis::{DynFamily, LastingStatistic};
use crate::gnss::GnssResiduals;

/// Every GNSS family, in report order (a change that stays found by the default statistic,
/// the matched filter).
pub fn all() -> Vec<Box<dyn DynFamily<GnssResiduals>>> {
    all_with(LastingStatistic::default())
}

/// Every GNSS family, in report order, a change that stays found by `lasting`.
pub fn all_with(lasting: LastingStatistic) -> Vec<Box<dyn DynFamily<GnssResiduals>>> {
    vec![
        Box::new(common_mode::CommonMode),
        Box::new(seasonal::Seasonal),
        Box::new(elevation::Elevation),
        Box::new(step::Step),
        Box::new(second_source::SecondSource),
        Box::new(lasting_source::LastingSource::WHOLE.by(lasting)),
        Box::new(lasting_source::LastingSource::RECENT.by(lasting)),
        Box::new(drift::Drift),
    ]
}

/// The names of [`all`], in report order.
pub fn names() -> Vec<&'static str> {
    all().iter().map(|f| f.name()).collect()
}

/// The families that find a point source (a pulse, a change that stays anywhere in the record
/// or in its last year): each declares the same term of F, a second source.
pub const SOURCES: [&str; 3] = ["second_source", "lasting_source", "recent_source"];

/// Whether `family` finds a point source ([`SOURCES`]).
pub fn is_source(family: &str) -> bool {
    SOURCES.contains(&family)
}

/// Whether `family` finds a change that stays (`lasting_source`, `recent_source`).
pub fn is_lasting(family: &str) -> bool {
    is_source(family) && family != "second_source"
}

/// `YYYY-MM-DD` of a day number (rounded).
pub fn iso_date(day: f64) -> String {
    if !day.is_finite() {
        return String::new();
    }
    let (y, m, d) = magic_core::time::civil_from_days(day.round() as i64);
    format!("{y:04}-{m:02}-{d:02}")
}

/// Three stations in a row, 5 km apart, named A, B, C (the reconciling rules' tests).
#[cfg(test)]
pub(crate) fn three_stations() -> crate::gnss::Network {
    let at = |x_km: f64| magic_core::mogi::Station {
        x_km,
        y_km: 0.0,
        z_km: 0.0,
    };
    crate::gnss::Network {
        names: vec!["A".into(), "B".into(), "C".into()],
        stations: vec![at(0.0), at(5.0), at(10.0)],
    }
}
