//! From a folder of NGL `tenv3` files to a training set in the paper's release layout
//! (`magic prepare`).
//!
//! 1. The files are read ([`crate::gnss::tenv3`]): one row per calendar day, displacements in mm,
//!    NaN where a station has no good line.
//! 2. Each station is placed in a local east/north/up frame ([`crate::gnss::geodesy`]) about the
//!    network's centre (the mean latitude and longitude, on the ellipsoid; or a given origin)
//!    from the median latitude, longitude (wrapped: NGL does not wrap it) and height of its
//!    lines.
//! 3. With `detrend`, each station's velocity is estimated per component by MIDAS
//!    ([`midas`]: pairs across a listed step skipped) and removed.
//! 4. The steps of an NGL steps file ([`steps`]: equipment changes and earthquakes) at the
//!    network's stations are estimated from the days around them ([`offsets`]) and removed.
//! 5. Each channel is taken relative to its median over the [`REFERENCE_DAYS`] from the
//!    network's reference day (the first day on which every station has data): displacements,
//!    and the source's ΔV, are then changes since the start of the record, which is what F
//!    produces (zero without a source, a declared step's offset after its epoch). A single
//!    reference day would put that day's noise into every value, an offset F cannot produce.
//!    Days on which no station has data are left out; a day with some stations down keeps its
//!    row, with those channels missing.
//! 6. The days are split by date ([`splits`]), standardised with the training period's mean and
//!    standard deviation per channel (over the days each channel has data), and the source's
//!    bounds are derived from the network ([`crate::gnss::SourceBounds::from_network`]).
//!
//! [`write()`] lays the result out as the release does, with `bounds.json` and a `prepare.json`
//! saying what was done (origin, stations, velocities, offsets, periods).

pub mod midas;
pub mod offsets;
pub mod splits;
pub mod steps;

use super::geodesy::{wrap_longitude, LocalFrame};
use super::tenv3::{self, format_date, Reference, StationSeries, Tenv3Error};
use super::{GnssProblem, Network, SourceBounds};
use crate::data::{Dataset, Split, SplitName};
use anyhow::{bail, Context, Result};
use magic_core::mogi::Station;
use serde::Serialize;
use splits::DateRange;
use std::path::{Path, PathBuf};

/// What `prepare` does.
#[derive(Clone, Debug)]
pub struct PrepareOptions {
    /// An NGL steps file.
    pub steps: Option<PathBuf>,
    /// Remove each station's MIDAS trend.
    pub detrend: bool,
    /// The test period (default: the first 20 % of the days).
    pub test: Option<DateRange>,
    /// The validation period (default: the last 15 % of the days).
    pub valid: Option<DateRange>,
    /// Depth range of the source, km.
    pub depth_km: [f64; 2],
    /// Margin around the stations' box for the source's x and y, km.
    pub margin_km: f64,
    /// Origin (latitude, longitude °) of the local frame (default: the network's centre).
    pub origin: Option<[f64; 2]>,
    /// Half-width of the window either side of a step, days.
    pub step_window_days: f64,
}

/// Default depth range of the source, km (the paper's Table 2).
pub const DEFAULT_DEPTH_KM: [f64; 2] = [2.0, 20.0];

/// Default margin around the stations' box, km.
pub const DEFAULT_MARGIN_KM: f64 = 2.0;

impl Default for PrepareOptions {
    fn default() -> Self {
        PrepareOptions {
            steps: None,
            detrend: false,
            test: None,
            valid: None,
            depth_km: DEFAULT_DEPTH_KM,
            margin_km: DEFAULT_MARGIN_KM,
            origin: None,
            step_window_days: offsets::STEP_WINDOW_DAYS,
        }
    }
}

/// A step as applied at a station.
#[derive(Clone, Debug, Serialize)]
pub struct StepApplied {
    /// `YYYY-MM-DD`.
    pub date: String,
    /// Offset removed (mm, east, north, up; `None` where too few days surround it).
    pub offset_mm: [Option<f64>; 3],
}

/// What was found and done for one station.
#[derive(Clone, Debug, Serialize)]
pub struct StationReport {
    /// Name.
    pub name: String,
    /// Latitude, longitude (°, wrapped) and ellipsoidal height (m).
    pub geodetic: [f64; 3],
    /// East, north, up of the origin (km).
    pub enu_km: [f64; 3],
    /// Days with data.
    pub days: usize,
    /// MIDAS velocity removed (mm/yr, east, north, up; `None` without `detrend` or with too
    /// little data) and its standard error.
    pub velocity_mm_yr: [Option<[f64; 2]>; 3],
    /// Listed steps applied.
    pub steps: Vec<StepApplied>,
}

/// What `prepare` did: written as `prepare.json`.
#[derive(Clone, Debug, Serialize)]
pub struct PrepareReport {
    /// Origin of the local frame: latitude, longitude (°), height (m).
    pub origin: [f64; 3],
    /// Per station.
    pub stations: Vec<StationReport>,
    /// Entries of the steps file at stations not in the network (ignored).
    pub steps_other_stations: usize,
    /// Days kept (with at least one station's data), first and last.
    pub days: usize,
    /// First and last day.
    pub span: String,
    /// Days left out because no station had data.
    pub empty_days: usize,
    /// Share of missing channels over the days kept.
    pub missing_share: f64,
    /// The test and validation periods; the rest is training.
    pub test: String,
    /// See `test`.
    pub valid: String,
    /// Rows of the train, valid and test splits.
    pub rows: [usize; 3],
    /// The source's bounds (x, y, depth km, ΔV 10⁶ m³).
    pub bounds: [[f64; 2]; 4],
}

/// The prepared dataset, what was done, and the input's problems.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// Network, standardised splits and source bounds.
    pub problem: GnssProblem,
    /// What was done.
    pub report: PrepareReport,
    /// Bad lines in the station and steps files (skipped).
    pub errors: Vec<Tenv3Error>,
    /// Remarks.
    pub notes: Vec<String>,
}

/// The stations with data and their geodetic positions; a station without a good line is left
/// out (noted), one whose file has no coordinates is an error.
fn placed(
    series: Vec<StationSeries>,
    notes: &mut Vec<String>,
) -> Result<Vec<(StationSeries, [f64; 3])>> {
    let mut out = Vec::new();
    for s in series {
        if s.epochs.is_empty() {
            notes.push(format!("station {}: no good line; left out", s.name));
            continue;
        }
        let geo = s.geodetic().with_context(|| {
            format!(
                "{}: station {} has no `_latitude(deg)`, `_longitude(deg)`, `__height(m)` fields (the older 20-field layout): its position is unknown",
                s.path, s.name
            )
        })?;
        out.push((s, geo));
    }
    if out.is_empty() {
        bail!("no station has a good line");
    }
    Ok(out)
}

/// The local frame: about `origin`, or the stations' mean latitude and longitude (longitudes
/// unwrapped about the first station's) on the ellipsoid.
fn frame(geo: &[[f64; 3]], origin: Option<[f64; 2]>) -> LocalFrame {
    let [lat, lon] = origin.unwrap_or_else(|| {
        let n = geo.len() as f64;
        let lon0 = geo[0][1];
        let lat = geo.iter().map(|g| g[0]).sum::<f64>() / n;
        let lon = geo
            .iter()
            .map(|g| lon0 + wrap_longitude(g[1] - lon0))
            .sum::<f64>()
            / n;
        [lat, lon]
    });
    LocalFrame::new(lat, lon, 0.0)
}

/// Removes the trend (with `detrend`) and the listed steps from one channel of the daily rows
/// (column `c`, rows from `first_day`); returns the velocity (mm/yr, ± its error) and the
/// offsets, one per step.
fn correct_channel(
    rows: &mut [Vec<f64>],
    c: usize,
    first_day: i64,
    step_days: &[f64],
    opts: &PrepareOptions,
) -> (Option<[f64; 2]>, Vec<Option<f64>>) {
    let idx: Vec<usize> = (0..rows.len())
        .filter(|&i| rows[i][c].is_finite())
        .collect();
    let days: Vec<f64> = idx.iter().map(|&i| (first_day + i as i64) as f64).collect();
    let mut x: Vec<f64> = idx.iter().map(|&i| rows[i][c]).collect();
    let mut velocity = None;
    if opts.detrend {
        if let Some(m) = midas::midas(&days, &x, step_days) {
            for (v, t) in x.iter_mut().zip(&days) {
                *v -= m.velocity * (t - first_day as f64) / midas::YEAR_DAYS;
            }
            velocity = Some([m.velocity, m.sigma_velocity]);
        }
    }
    let off = offsets::step_offsets(&days, &x, step_days, opts.step_window_days);
    offsets::remove_offsets(&days, &mut x, step_days, &off);
    for (k, &i) in idx.iter().enumerate() {
        rows[i][c] = x[k];
    }
    (velocity, off)
}

/// Removes the trend (with `detrend`) and the `listed` steps from station `s`'s channels of
/// `daily`; the station's report (without its position).
fn correct_station(
    daily: &mut tenv3::Daily,
    s: usize,
    sta: &StationSeries,
    listed: &[i64],
    opts: &PrepareOptions,
    notes: &mut Vec<String>,
) -> StationReport {
    let ns = daily.stations.len();
    let (first, last) = (sta.epochs[0].day, sta.epochs[sta.epochs.len() - 1].day);
    let (inside, outside): (Vec<i64>, Vec<i64>) =
        listed.iter().partition(|&&d| d > first && d <= last);
    for d in outside {
        notes.push(format!(
            "station {}: step on {} is outside its data ({} … {}); ignored",
            sta.name,
            format_date(d, '-'),
            format_date(first, '-'),
            format_date(last, '-')
        ));
    }
    let step_days: Vec<f64> = inside.iter().map(|&d| d as f64).collect();
    let mut velocity = [None; 3];
    let mut offs = vec![[None; 3]; inside.len()];
    for k in 0..3 {
        let (v, o) = correct_channel(
            &mut daily.rows,
            k * ns + s,
            daily.first_day,
            &step_days,
            opts,
        );
        if opts.detrend && v.is_none() {
            notes.push(format!(
                "station {} {}: too little data for a trend (no pair of days a year apart); not detrended",
                sta.name,
                ["east", "north", "up"][k]
            ));
        }
        velocity[k] = v;
        for (j, c) in o.into_iter().enumerate() {
            offs[j][k] = c;
        }
    }
    StationReport {
        name: sta.name.clone(),
        geodetic: [f64::NAN; 3],
        enu_km: [f64::NAN; 3],
        days: sta.epochs.len(),
        velocity_mm_yr: velocity,
        steps: inside
            .iter()
            .zip(offs)
            .map(|(&d, offset_mm)| StepApplied {
                date: format_date(d, '-'),
                offset_mm,
            })
            .collect(),
    }
}

/// Days from the reference day over which each channel's zero is taken (its median).
pub const REFERENCE_DAYS: i64 = 30;

/// Takes channel `c` of the daily rows relative to its median over the [`REFERENCE_DAYS`] from
/// `reference` (a day number; its first [`REFERENCE_DAYS`] values when it has none there).
fn zero_channel(daily: &mut tenv3::Daily, c: usize, reference: Option<i64>) {
    let first = daily.first_day;
    let finite: Vec<usize> = (0..daily.len())
        .filter(|&i| daily.rows[i][c].is_finite())
        .collect();
    let window: Vec<usize> = match reference {
        Some(r) => finite
            .iter()
            .copied()
            .filter(|&i| (r..r + REFERENCE_DAYS).contains(&(first + i as i64)))
            .collect(),
        None => vec![],
    };
    let window = if window.is_empty() {
        finite
            .iter()
            .copied()
            .take(REFERENCE_DAYS as usize)
            .collect()
    } else {
        window
    };
    let mut v: Vec<f64> = window.iter().map(|&i| daily.rows[i][c]).collect();
    let level = crate::numerics::median(&mut v);
    for &i in &finite {
        daily.rows[i][c] -= level;
    }
}

/// The steps file's step days per station in `names`, and how many entries were for other
/// stations.
fn read_steps(
    path: &Option<PathBuf>,
    names: &[String],
    errors: &mut Vec<Tenv3Error>,
) -> Result<(std::collections::BTreeMap<String, Vec<i64>>, usize)> {
    let Some(p) = path else {
        return Ok(Default::default());
    };
    let text =
        std::fs::read_to_string(p).with_context(|| format!("{}: cannot read", p.display()))?;
    let (entries, e) = steps::parse_steps(&p.display().to_string(), &text);
    errors.extend(e);
    Ok(steps::by_station(&entries, names))
}

/// Reads the `tenv3` files in `dir` and prepares the training set.
pub fn prepare(dir: &Path, opts: &PrepareOptions) -> Result<Prepared> {
    let read = tenv3::read_series(dir, None)?;
    let (mut errors, mut notes) = (read.errors, read.notes);
    let placed = placed(read.series, &mut notes)?;
    let geo: Vec<[f64; 3]> = placed.iter().map(|p| p.1).collect();
    let series: Vec<StationSeries> = placed.into_iter().map(|p| p.0).collect();
    let names: Vec<String> = series.iter().map(|s| s.name.clone()).collect();
    let frame = frame(&geo, opts.origin);
    let network = Network {
        names: names.clone(),
        stations: geo
            .iter()
            .map(|g| {
                let [e, n, u] = frame.enu(g[0], g[1], g[2]);
                Station {
                    x_km: e / 1000.0,
                    y_km: n / 1000.0,
                    z_km: u / 1000.0,
                }
            })
            .collect(),
    };
    let (mut daily, e, n) = tenv3::combine(&series, Reference::Auto);
    errors.extend(e);
    notes.extend(n);
    let (step_map, steps_other_stations) = read_steps(&opts.steps, &names, &mut errors)?;
    let stations = series
        .iter()
        .enumerate()
        .map(|(s, sta)| {
            let listed = step_map.get(&sta.name).map_or(&[][..], |v| v.as_slice());
            let mut r = correct_station(&mut daily, s, sta, listed, opts, &mut notes);
            r.geodetic = geo[s];
            let st = network.stations[s];
            r.enu_km = [st.x_km, st.y_km, st.z_km];
            r
        })
        .collect();
    let ns = series.len();
    for s in 0..ns {
        for k in 0..3 {
            let reference = daily.reference[s];
            zero_channel(&mut daily, k * ns + s, reference);
        }
    }
    let source_bounds = SourceBounds::from_network(&network, opts.margin_km, opts.depth_km)?;
    let (data, summary) = standardised(&daily, &network, opts)?;
    let report = PrepareReport {
        origin: frame.origin,
        stations,
        steps_other_stations,
        bounds: source_bounds.0,
        ..summary
    };
    errors.sort_by(|a, b| (&a.path, a.line, a.column).cmp(&(&b.path, b.line, b.column)));
    Ok(Prepared {
        problem: GnssProblem {
            network,
            data,
            source_bounds,
        },
        report,
        errors,
        notes,
    })
}

/// The days with data split by date and standardised on the training split; the report's
/// counts and periods (its other fields empty).
fn standardised(
    daily: &tenv3::Daily,
    network: &Network,
    opts: &PrepareOptions,
) -> Result<(Dataset, PrepareReport)> {
    let keep: Vec<usize> = (0..daily.len())
        .filter(|&i| daily.rows[i].iter().any(|v| v.is_finite()))
        .collect();
    let days: Vec<i64> = keep.iter().map(|&i| daily.first_day + i as i64).collect();
    let (split, test, valid) = splits::assign(&days, opts.test, opts.valid)?;
    let nc = 3 * network.len();
    let columns = network.channel_names();
    let (mut sum, mut sq, mut count) = (vec![0.0; nc], vec![0.0; nc], vec![0usize; nc]);
    for (&i, s) in keep.iter().zip(&split) {
        if *s == SplitName::Train {
            for (c, v) in daily.rows[i]
                .iter()
                .enumerate()
                .filter(|(_, v)| v.is_finite())
            {
                sum[c] += v;
                sq[c] += v * v;
                count[c] += 1;
            }
        }
    }
    let mut mean = vec![0.0; nc];
    let mut scale = vec![0.0; nc];
    for c in 0..nc {
        if count[c] < 2 {
            bail!(
                "channel `{}` has {} days of data in the training period (the days outside the test and validation periods): too few to standardise (choose other periods, or leave the station out)",
                columns[c],
                count[c]
            );
        }
        mean[c] = sum[c] / count[c] as f64;
        // Population standard deviation (as the release's scale), NaN-aware.
        scale[c] = (sq[c] / count[c] as f64 - mean[c] * mean[c])
            .max(0.0)
            .sqrt();
        if scale[c] <= 0.0 {
            bail!(
                "channel `{}` is constant over the training period",
                columns[c]
            );
        }
    }
    let mut parts = [Split::default(), Split::default(), Split::default()];
    for (&i, s) in keep.iter().zip(&split) {
        let row: Vec<f32> = daily.rows[i]
            .iter()
            .enumerate()
            .map(|(c, v)| ((v - mean[c]) / scale[c]) as f32)
            .collect();
        parts[s.index()].x.push(row);
        parts[s.index()].dates.push(daily.date(i));
    }
    let cells = keep.len() * nc;
    let missing = keep
        .iter()
        .map(|&i| daily.rows[i].iter().filter(|v| !v.is_finite()).count())
        .sum::<usize>();
    let rows = [parts[0].len(), parts[1].len(), parts[2].len()];
    let [train, valid_split, test_split] = parts;
    let report = PrepareReport {
        origin: [0.0; 3],
        stations: vec![],
        steps_other_stations: 0,
        days: keep.len(),
        span: format!(
            "{}..{}",
            format_date(days[0], '-'),
            format_date(days[days.len() - 1], '-')
        ),
        empty_days: daily.len() - keep.len(),
        missing_share: missing as f64 / cells.max(1) as f64,
        test: test.text(),
        valid: valid.text(),
        rows,
        bounds: [[0.0; 2]; 4],
    };
    let data = Dataset {
        columns,
        mean,
        scale,
        train,
        valid: valid_split,
        test: test_split,
        source: "tenv3 files".into(),
    };
    data.check()?;
    Ok((data, report))
}

/// Writes the release layout (with `bounds.json`) and `prepare.json` into `out`.
pub fn write(p: &Prepared, out: &Path) -> Result<()> {
    super::data::write_dir(&p.problem, out)?;
    p.problem.source_bounds.write_dir(out)?;
    let path = out.join("prepare.json");
    std::fs::write(&path, serde_json::to_string_pretty(&p.report)?)
        .with_context(|| format!("{}: cannot write", path.display()))
}
