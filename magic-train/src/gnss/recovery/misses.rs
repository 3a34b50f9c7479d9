//! Why an injected effect was missed: on which bound of its search grid it was rejected, or
//! whether it was located but not significant, significant but off, or neither — counted per
//! scenario and noise model over the placements (`magic synth-check` prints the table).

use super::{Found, Recovery};
use crate::analysis::{Rejection, Side};
use std::fmt::Write as _;

/// Which bound of the search grid a source was rejected on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bound {
    /// The shallowest depth of the grid: a field concentrated on the nearest stations.
    Shallowest,
    /// The deepest depth: a field nearly uniform over the network.
    Deepest,
    /// A horizontal edge of the grid.
    Edge,
}

/// The bound of the grid `why` names, if the bound rule rejected the candidate.
fn bound_of(why: &Rejection) -> Option<Bound> {
    Some(match why.bound()? {
        ("depth", Side::Low) => Bound::Shallowest,
        ("depth", Side::High) => Bound::Deepest,
        _ => Bound::Edge,
    })
}

/// Why an injected effect was not found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Miss {
    /// Rejected on a bound of its search grid.
    OnBound(Bound),
    /// Rejected by another rule (e.g. a step's scan statistic not above the surrogates').
    Rejected,
    /// Its parameters recovered, not significant.
    NotSignificant,
    /// Significant, its parameters not recovered.
    ParamsOff,
    /// Neither (or its family not analysed).
    Neither,
}

/// Why `f` was missed; `None` if it was found.
pub fn miss(f: &Found) -> Option<Miss> {
    if f.found() {
        return None;
    }
    Some(match (&f.rejected, f.significant, f.params_ok) {
        (Some(why), _, _) => bound_of(why).map_or(Miss::Rejected, Miss::OnBound),
        (None, false, true) => Miss::NotSignificant,
        (None, true, false) => Miss::ParamsOff,
        _ => Miss::Neither,
    })
}

/// The columns of [`miss_table`] after "found", in order.
const COLUMNS: [(Miss, &str); 7] = [
    (
        Miss::OnBound(Bound::Shallowest),
        "on the grid's shallowest depth",
    ),
    (Miss::OnBound(Bound::Deepest), "on its deepest depth"),
    (Miss::OnBound(Bound::Edge), "on its horizontal edge"),
    (Miss::Rejected, "rejected by another rule"),
    (Miss::NotSignificant, "parameters right, not significant"),
    (Miss::ParamsOff, "significant, parameters off"),
    (Miss::Neither, "neither"),
];

/// Markdown: a line per scenario, noise model and injected effect (placements together) of
/// runs, found, and each [`Miss`]; scenarios without an injected effect are left out.
pub fn miss_table(rows: &[Recovery]) -> String {
    let mut s = String::from("| scenario | noise | effect | runs | found |");
    for (_, name) in COLUMNS {
        let _ = write!(s, " {name} |");
    }
    s.push_str(&format!("\n|{}\n", "---|".repeat(5 + COLUMNS.len())));
    let mut keys: Vec<(&str, &str, usize, &str)> = Vec::new();
    for r in rows {
        for (i, f) in r.effects.iter().enumerate() {
            let k = (r.scenario.as_str(), r.noise.as_str(), i, f.family.as_str());
            if !keys.contains(&k) {
                keys.push(k);
            }
        }
    }
    for (sc, no, i, fam) in keys {
        let g: Vec<&Found> = rows
            .iter()
            .filter(|r| (r.scenario.as_str(), r.noise.as_str()) == (sc, no))
            .filter_map(|r| r.effects.get(i))
            .collect();
        let count = |m: Option<Miss>| g.iter().filter(|f| miss(f) == m).count();
        let _ = write!(s, "| {sc} | {no} | {fam} | {} | {} |", g.len(), count(None));
        for (m, _) in COLUMNS {
            let _ = write!(s, " {} |", count(Some(m)));
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn found(significant: bool, params_ok: bool, rejected: Option<Rejection>) -> Found {
        Found {
            family: "second_source".into(),
            significant,
            rank: Some(1),
            params_ok,
            detail: String::new(),
            rejected,
            at_truth: None,
        }
    }

    fn row(placement: &str, f: Found) -> Recovery {
        Recovery::single("second_source_near", "paper", placement, f)
    }

    #[test]
    fn each_miss_has_its_column() {
        let shallow = Rejection::OnBound {
            coordinate: "depth",
            unit: "km",
            value: 2.0,
            lo: 2.0,
            hi: 20.0,
        };
        let stat = Rejection::StatisticNotAbove {
            statistic: 1.0,
            largest: 2.0,
        };
        let rows = [
            row("train", found(true, true, None)),
            row("valid", found(false, true, Some(shallow))),
            row("test", found(false, true, None)),
            row("train", found(true, false, None)),
            row("valid", found(false, false, Some(stat))),
            row("test", found(false, false, None)),
        ];
        assert_eq!(miss(&rows[0].effects[0]), None);
        let t = miss_table(&rows);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 3, "{t}");
        assert_eq!(
            lines[2],
            "| second_source_near | paper | second_source | 6 | 1 | 1 | 0 | 0 | 1 | 1 | 1 | 1 |"
        );
    }

    /// Each bound of the grid by its coordinate and the nearer end of its range (what the
    /// removed string parser's test held for the reasons).
    #[test]
    fn bounds_by_coordinate_and_side() {
        let on = |coordinate, value, lo, hi| {
            bound_of(&Rejection::OnBound {
                coordinate,
                unit: "km",
                value,
                lo,
                hi,
            })
        };
        assert_eq!(on("depth", 2.1, 2.0, 20.0), Some(Bound::Shallowest));
        assert_eq!(on("depth", 20.0, 2.0, 20.0), Some(Bound::Deepest));
        assert_eq!(on("x", -9.0, -9.0, 10.0), Some(Bound::Edge));
        assert_eq!(on("y", 9.875, -9.0, 10.0), Some(Bound::Edge));
        assert_eq!(bound_of(&Rejection::PartOf("its onset".into())), None);
    }
}
