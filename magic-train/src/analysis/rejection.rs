//! Why a fitted effect cannot count as a discovery whatever its score: one reason, kept as data
//! so the tables can count what rejected it (which bound of a grid) and printed in words in the
//! reports and the JSON.

use std::fmt;

/// Which side of its range a coordinate on the bound lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The range's lower end.
    Low,
    /// Its upper end.
    High,
}

/// Why a candidate cannot count as a discovery.
///
/// ```
/// use magic_train::analysis::{Rejection, Side};
/// let r = Rejection::OnBound { coordinate: "depth", unit: "km", value: 2.0, lo: 2.0, hi: 20.0 };
/// assert_eq!(r.to_string(), "on the bound of the search grid (depth 2.0 km in [2.0, 20.0])");
/// assert_eq!(r.bound(), Some(("depth", Side::Low)));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub enum Rejection {
    /// Its position on the bound of the search grid: a fit the grid stopped is not located.
    OnBound {
        /// The coordinate on its bound (`x`, `y`, `depth`).
        coordinate: &'static str,
        /// Its unit.
        unit: &'static str,
        /// Its value.
        value: f64,
        /// The grid's range of it.
        lo: f64,
        /// See `lo`.
        hi: f64,
    },
    /// Its detection statistic not above every surrogate's
    /// ([`Family::statistic`](super::Family::statistic)).
    StatisticNotAbove {
        /// The fit's statistic.
        statistic: f64,
        /// The surrogates' largest.
        largest: f64,
    },
    /// A source whose field is mostly what a move of the main source produces: the share of it
    /// no such move can produce is below the least that tells the two apart.
    Unresolvable {
        /// The share of its field (in norm) beyond the main source's span (and the declared
        /// sources' fields).
        share: f64,
        /// The least share accepted.
        least: f64,
        /// F declares extra sources, whose fields the span holds too.
        beside_declared: bool,
    },
    /// F declares an extra source the main source trades with (its field mostly in the main
    /// source's span), and the candidate lies across the main source from it: the trade's
    /// mirror image, not told from it.
    BesideTrade {
        /// The declared source's share of its field (in norm) beyond the main source's span.
        share: f64,
        /// The least share beside which another source is taken anywhere.
        least: f64,
        /// The angle (degrees) between the two, around the main source seen from above.
        angle: f64,
        /// The least angle at which a candidate is taken for the mirror image.
        least_angle: f64,
    },
    /// A source one station sees alone: most of its pattern at that station, whose own motion
    /// (a step, a settling monument) it stands for, and the other stations do not confirm it
    /// ([`HeldPart`](super::HeldPart)).
    OneStation {
        /// The station.
        station: String,
        /// The share of the pattern's energy it holds.
        share: f64,
        /// The largest share accepted without the other stations confirming it.
        most: f64,
        /// The source's score on the other stations alone (share of the residual variance).
        without: f64,
        /// The score they had to pass (NaN: no surrogates to judge them by).
        needed: f64,
    },
    /// Its fit over the whole record, the one F would take, adds nothing (a drift whose
    /// held-out fits each found a station in part of the record, though no station's rate
    /// stands out over all of it), in words that say why.
    NothingToAdd(&'static str),
    /// Taken for part of another candidate's effect (a step at a lasting source's onset), in
    /// words that name it ([`Problem::reconcile`](crate::problem::Problem::reconcile)).
    PartOf(String),
}

impl Rejection {
    /// The coordinate on its bound and the side of the range it is nearer, if the grid's bound
    /// rejected it.
    pub fn bound(&self) -> Option<(&'static str, Side)> {
        match *self {
            Rejection::OnBound {
                coordinate,
                value,
                lo,
                hi,
                ..
            } => Some((
                coordinate,
                if (value - lo).abs() <= (hi - value).abs() {
                    Side::Low
                } else {
                    Side::High
                },
            )),
            _ => None,
        }
    }
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Rejection::OnBound {
                coordinate,
                unit,
                value,
                lo,
                hi,
            } => write!(
                f,
                "on the bound of the search grid ({coordinate} {value:.1} {unit} in \
                 [{lo:.1}, {hi:.1}])"
            ),
            Rejection::StatisticNotAbove { statistic, largest } => write!(
                f,
                "detection statistic {statistic:.3} not above the surrogates' largest, \
                 {largest:.3}"
            ),
            Rejection::Unresolvable {
                share,
                least,
                beside_declared,
            } => write!(
                f,
                "its field mostly a move of the main source{} ({share:.2} of it beyond, at least \
                 {least:.2} needed)",
                if *beside_declared {
                    " and a change of the declared sources"
                } else {
                    ""
                }
            ),
            Rejection::BesideTrade {
                share,
                least,
                angle,
                least_angle,
            } => write!(
                f,
                "across the main source ({angle:.0}° around it, {least_angle:.0}° or more) from a \
                 declared source it trades with ({share:.2} of that source's field beyond the \
                 main source's span, at least {least:.2} needed for another anywhere)"
            ),
            Rejection::OneStation {
                station,
                share,
                most,
                without,
                needed,
            } => {
                write!(
                    f,
                    "seen by one station: {station} holds {share:.2} of its field's energy (more \
                     than {most:.2}) and the other stations alone explain {without:.4} of the \
                     residual variance, "
                )?;
                if needed.is_nan() {
                    f.write_str("with no surrogates to judge them by")
                } else {
                    write!(f, "{needed:.4} needed")
                }
            }
            Rejection::NothingToAdd(why) => write!(f, "nothing to add: {why}"),
            Rejection::PartOf(why) => f.write_str(why),
        }
    }
}

/// Reported in words, as [`fmt::Display`] writes it.
impl serde::Serialize for Rejection {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn depth(value: f64) -> Rejection {
        Rejection::OnBound {
            coordinate: "depth",
            unit: "km",
            value,
            lo: 2.0,
            hi: 20.0,
        }
    }

    #[test]
    fn a_bound_names_its_side() {
        assert_eq!(depth(2.1).bound(), Some(("depth", Side::Low)));
        assert_eq!(depth(19.9).bound(), Some(("depth", Side::High)));
        let stat = Rejection::StatisticNotAbove {
            statistic: 9.1,
            largest: 12.0,
        };
        assert_eq!(stat.bound(), None);
        assert_eq!(Rejection::PartOf("its onset".into()).bound(), None);
        let empty = Rejection::NothingToAdd("no station's rate stands out");
        assert_eq!(empty.bound(), None);
        assert_eq!(
            empty.to_string(),
            "nothing to add: no station's rate stands out"
        );
        let near = Rejection::Unresolvable {
            share: 0.13,
            least: 0.25,
            beside_declared: false,
        };
        assert_eq!(near.bound(), None);
        assert_eq!(
            near.to_string(),
            "its field mostly a move of the main source (0.13 of it beyond, at least 0.25 needed)"
        );
        let one = Rejection::OneStation {
            station: "AKLV".into(),
            share: 0.912,
            most: 0.75,
            without: 0.0003,
            needed: 0.0011,
        };
        assert_eq!(one.bound(), None);
        assert_eq!(
            one.to_string(),
            "seen by one station: AKLV holds 0.91 of its field's energy (more than 0.75) and the \
             other stations alone explain 0.0003 of the residual variance, 0.0011 needed"
        );
        let unjudged = Rejection::OneStation {
            station: "AKLV".into(),
            share: 0.912,
            most: 0.75,
            without: 0.0003,
            needed: f64::NAN,
        };
        assert!(unjudged
            .to_string()
            .ends_with("0.0003 of the residual variance, with no surrogates to judge them by"));
    }

    #[test]
    fn words_and_json_agree() {
        let stat = Rejection::StatisticNotAbove {
            statistic: 9.1,
            largest: 12.0,
        };
        let words = "detection statistic 9.100 not above the surrogates' largest, 12.000";
        assert_eq!(stat.to_string(), words);
        assert_eq!(serde_json::to_value(&stat).unwrap(), words);
        assert_eq!(
            serde_json::to_value(depth(19.9)).unwrap(),
            "on the bound of the search grid (depth 19.9 km in [2.0, 20.0])"
        );
    }
}
