//! NGL tenv3 files → daily rows → inversion: a known Mogi displacement series written as station
//! files with the mess real archives have (gaps, a late station, integer-part resets, an old
//! 20-field file, unknown sigmas, CRLF line ends, bad lines, a duplicated and an unordered date),
//! read back to exactly one row and one inversion result per calendar day.

use magic_core::mogi::{self, Station};
use magic_core::{invert, Flags, Model, Variant, Workspace};
use magic_tests::{random_mogi_model, TempDir};
use magic_train::data::records;
use magic_train::gnss::synth;
use magic_train::gnss::tenv3::{self, Reference};
use std::collections::BTreeSet;
use std::path::Path;

const N_DAYS: i64 = 30;
/// A daily displacement read back from the files against the one written (mm): positions are
/// written in m with 6 decimals, ±5e-4 mm each, so a displacement (the difference of two) is off
/// by up to 1e-3 mm; measured 9.9e-4. The bound is that analytic worst case plus 5 % for the f64
/// arithmetic on the way.
const READ_BACK_MAX_ERROR_MM: f64 = 1.05e-3;
const MJD_1970: i64 = 40_587;
const MONTHS: [&str; 12] = [
    "JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV", "DEC",
];
const HEADER: &str = "site YYMMMDD yyyy.yyyy __MJD week d reflon _e0(m) __east(m) ____n0(m) _north(m) u0(m) ____up(m) _ant(m) sig_e(m) sig_n(m) sig_u(m) __corr_en __corr_eu __corr_nu _latitude(deg) _longitude(deg) __height(m)";

fn day0() -> i64 {
    magic_core::time::days_from_civil(2010, 7, 20)
}

/// The fields of one tenv3 line (23, or the first 20 for the old layout).
fn fields(site: &str, day: i64, int: [i64; 3], frac: [f64; 3], sig: [f64; 3]) -> Vec<String> {
    let (y, m, d) = magic_core::time::civil_from_days(day);
    let mjd = day + MJD_1970;
    let mut f = vec![
        site.to_string(),
        format!("{:02}{}{:02}", y % 100, MONTHS[m as usize - 1], d),
        format!("{:.4}", y as f64 + (m as f64 - 0.5) / 12.0),
        mjd.to_string(),
        ((mjd - 44_244) / 7).to_string(),
        ((mjd - 44_244) % 7).to_string(),
        "-166".into(),
    ];
    for k in 0..3 {
        f.push(int[k].to_string());
        f.push(format!("{:.6}", frac[k]));
    }
    f.push("0.0000".into());
    for s in sig {
        f.push(format!("{s:.6}"));
    }
    for v in [
        "0.0123",
        "-0.0204",
        "0.0071",
        "54.1271930",
        "-165.9743172",
        "410.3188",
    ] {
        f.push(v.into());
    }
    f
}

/// 1-based character column where field `k` (1-based) of `line` starts, or one past the end.
fn column(line: &str, k: usize) -> usize {
    let mut n = 0;
    let mut prev_space = true;
    for (i, ch) in line.chars().enumerate() {
        if !ch.is_whitespace() && prev_space {
            n += 1;
            if n == k {
                return i + 1;
            }
        }
        prev_space = ch.is_whitespace();
    }
    line.chars().count() + 1
}

/// The known series: the Mogi field of a breathing source at the 12 Akutan stations (mm).
fn truth() -> Vec<Vec<f64>> {
    let stations: Vec<Station> = synth::AKUTAN
        .iter()
        .map(|s| Station {
            x_km: s.1,
            y_km: s.2,
            z_km: s.3,
        })
        .collect();
    (0..N_DAYS)
        .map(|t| {
            let dv = 3.0 * (t as f64 / 6.0).sin() + 0.1 * t as f64;
            let mut u = vec![0.0; 36];
            mogi::field(&stations, &[0.3, 0.2, 7.0, dv], &mut u).unwrap();
            u
        })
        .collect()
}

struct Written {
    /// (file name, line, column) of every bad line.
    bad: Vec<(String, usize, usize)>,
    /// (station, day) cells that must be missing.
    missing: BTreeSet<(usize, i64)>,
}

/// Writes one file per station; returns what the reader must report.
/// Station `s`'s position on day `t` as NGL writes it: integer metres and a fraction, the known
/// displacement `u` (mm) added to a base position. AKLV's fraction has drifted past 10 m; NGL
/// moves 10 m into the integer part on day 15 (east) and day 25 (up), the position unchanged.
fn position(name: &str, s: usize, t: i64, u: &[Vec<f64>]) -> ([i64; 3], [f64; 3]) {
    let mut int = [
        -7000 - 500 * s as i64,
        6_000_000 + 1000 * s as i64,
        300 + 10 * s as i64,
    ];
    let base_frac = [0.25, 0.5, 0.125];
    let mut frac: [f64; 3] =
        std::array::from_fn(|k| base_frac[k] + u[t as usize][k * 12 + s] / 1000.0);
    if name == "AKLV" {
        frac[0] += 9.9;
        frac[2] -= 9.95;
        if t >= 15 {
            int[0] += 10;
            frac[0] -= 10.0;
        }
        if t >= 25 {
            int[2] -= 10;
            frac[2] += 10.0;
        }
    }
    (int, frac)
}

/// AV06's bad lines: spoils the fields `g` of day `t` (position `int`, day number `day`) and
/// returns the 1-based field the reader must name (99: the field count), or 0 for a good line.
fn spoil_av06(t: i64, g: &mut Vec<String>, int: [i64; 3], day: i64) -> usize {
    match t {
        4 => {
            g[10] = "0.12x4".into(); // `_north(m)` not a number
            11
        }
        6 => {
            g.pop(); // 22 fields
            99
        }
        8 => {
            g[16] = "inf".into(); // `sig_u(m)`
            17
        }
        9 => {
            g[11] = (int[2] + 800).to_string(); // `u0(m)` corrupt: 800 m up
            13
        }
        12 => {
            g[3] = (day + MJD_1970 - 1).to_string(); // MJD disagrees with YYMMMDD
            4
        }
        16 => {
            g.push("extra".into()); // 24 fields
            24
        }
        _ => 0,
    }
}

fn write_network(dir: &Path, u: &[Vec<f64>]) -> Written {
    let mut bad = Vec::new();
    let mut missing = BTreeSet::new();
    for (s, st) in synth::AKUTAN.iter().enumerate() {
        let name = st.0;
        let file = format!("{name}.tenv3");
        let old = name == "AKMO";
        let sep = if name == "AV06" { "  " } else { " " };
        let mut lines: Vec<String> = vec![if old {
            HEADER.split(' ').take(20).collect::<Vec<_>>().join(" ")
        } else {
            HEADER.to_string()
        }];
        let mut bad_here = |lines: &Vec<String>, line: &str, field: usize| {
            bad.push((file.clone(), lines.len() + 1, column(line, field)));
        };
        let mut delayed: Option<String> = None;
        for t in 0..N_DAYS {
            let day = day0() + t;
            let gap = t == 20 // nobody observed this day
                || (name == "AKGG" && (5..=8).contains(&t))
                || (name == "AV08" && t < 2); // a late station: the common reference is day 2
            if gap {
                missing.insert((s, t));
                continue;
            }
            let (int, frac) = position(name, s, t, u);
            let sig = if name == "AKRB" && (10..14).contains(&t) {
                [9.99999; 3]
            } else {
                [0.0011, 0.0012, 0.0045]
            };
            let mut f = fields(name, day, int, frac, sig);
            if old {
                f.truncate(20);
            }
            let good = f.join(sep);
            if name == "AV06" {
                let mut g = f.clone();
                let field = spoil_av06(t, &mut g, int, day);
                if field > 0 {
                    let l = g.join(sep);
                    bad_here(&lines, &l, field);
                    lines.push(l);
                    missing.insert((s, t));
                    continue;
                }
            }
            if name == "AV07" && t == 14 {
                // Written later, after day 17: out of order, skipped.
                delayed = Some(good);
                missing.insert((s, t));
                continue;
            }
            lines.push(good.clone());
            if name == "AV07" && t == 10 {
                // The same date again with other values: the first line is kept.
                let mut g = f.clone();
                g[12] = format!("{:.6}", frac[2] + 0.005);
                let l = g.join(sep);
                bad_here(&lines, &l, 2);
                lines.push(l);
            }
            if name == "AV07" && t == 17 {
                let l = delayed.take().unwrap();
                bad_here(&lines, &l, 2);
                lines.push(l);
            }
        }
        let eol = if name == "AV10" { "\r\n" } else { "\n" };
        std::fs::write(dir.join(&file), lines.join(eol) + eol).unwrap();
    }
    Written { bad, missing }
}

fn model_bytes() -> Vec<u8> {
    random_mogi_model(Variant::C, 7).encode().unwrap()
}

#[test]
fn tenv3_files_to_one_inversion_per_day() {
    let tmp = TempDir::new("tenv3");
    let u = truth();
    let w = write_network(&tmp.0, &u);
    let bytes = model_bytes();
    let model = Model::decode(&bytes).unwrap();
    let names = tenv3::model_station_names(&model).unwrap();
    assert_eq!(
        names,
        synth::AKUTAN
            .iter()
            .map(|s| s.0.to_string())
            .collect::<Vec<_>>()
    );

    let read = tenv3::read_dir(&tmp.0, Some(&names), Reference::Auto).unwrap();
    let msgs: Vec<String> = read.errors.iter().map(|e| e.to_string()).collect();
    let got: Vec<(String, usize, usize)> = read
        .errors
        .iter()
        .map(|e| {
            (
                Path::new(&e.path)
                    .file_name()
                    .unwrap()
                    .to_string_lossy()
                    .into_owned(),
                e.line,
                e.column,
            )
        })
        .collect();
    let mut want = w.bad.clone();
    want.sort();
    assert_eq!(got, want, "\n{}", msgs.join("\n"));
    eprintln!("reported as expected:\n{}", msgs.join("\n"));
    assert!(read.notes.is_empty(), "{:?}", read.notes);
    for m in &msgs {
        assert!(
            m.contains("expected"),
            "every message says what was expected: {m}"
        );
    }

    // One row per calendar day, first to last, the reference the first day all stations report.
    let d = &read.daily;
    assert_eq!(d.len(), N_DAYS as usize);
    assert_eq!(d.first_day, day0());
    assert_eq!(d.date(0), "2010.07.20");
    assert_eq!(d.date(N_DAYS as usize - 1), "2010.08.18");
    assert!(
        d.reference.iter().all(|r| *r == Some(day0() + 2)),
        "{:?}",
        d.reference
    );
    let mut worst = 0f64;
    for t in 0..N_DAYS as usize {
        for s in 0..12 {
            for k in 0..3 {
                let v = d.rows[t][k * 12 + s];
                if w.missing.contains(&(s, t as i64)) {
                    assert!(
                        v.is_nan(),
                        "day {t} station {s} component {k}: expected a gap, found {v}"
                    );
                } else {
                    let want = u[t][k * 12 + s] - u[2][k * 12 + s];
                    worst = worst.max((v - want).abs());
                    assert!(
                        (v - want).abs() <= READ_BACK_MAX_ERROR_MM,
                        "day {t} station {s} component {k}: {v} mm, want {want} mm"
                    );
                }
            }
        }
    }

    eprintln!("tenv3 read back: largest difference {worst:.3e} mm");
    // Through the CSV `magic invert` reads: one result line per day, in date order.
    let csv = tmp.0.join("daily.csv");
    d.write_csv(&csv).unwrap();
    let rows = records::read_obs(&csv, &model, false).unwrap();
    assert_eq!(rows.len(), N_DAYS as usize);
    let dates: Vec<String> = rows.iter().map(|r| r.date.clone().unwrap()).collect();
    let expect: Vec<String> = (0..N_DAYS as usize).map(|i| d.date(i)).collect();
    assert_eq!(dates, expect, "no day lost, duplicated or reordered");
    let lines = records::invert_rows(&model, &rows);
    assert_eq!(lines.len(), N_DAYS as usize);

    let mut ws = Workspace::default();
    for (t, line) in lines.iter().enumerate() {
        let gaps = (0..12).any(|s| w.missing.contains(&(s, t as i64)));
        let direct = invert::<f64>(&model, &d.obs(t), &mut ws);
        if t == 20 {
            assert!(
                line.starts_with("error,") && line.contains("too few"),
                "day {t}: {line}"
            );
            assert!(direct.is_err());
            continue;
        }
        let inv = direct.unwrap_or_else(|e| panic!("day {t}: {e}"));
        assert_eq!(inv.flags.has(Flags::MISSING), gaps, "day {t}");
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 7, "day {t}: {line}");
        let flags: u8 = f[5].parse().unwrap();
        assert_eq!(flags & Flags::MISSING != 0, gaps, "day {t}: {line}");
        assert_eq!(
            flags, inv.flags.0,
            "day {t}: CSV path and direct inversion agree"
        );
    }
}

#[test]
fn reference_date_and_station_list_order() {
    let tmp = TempDir::new("tenv3-ref");
    let u = truth();
    write_network(&tmp.0, &u);
    // A stations.json-like order (reversed) with a station that has no file.
    let mut names: Vec<String> = synth::AKUTAN
        .iter()
        .rev()
        .map(|s| s.0.to_string())
        .collect();
    names.push("XXXX".into());
    let read = tenv3::read_dir(&tmp.0, Some(&names), Reference::Day(day0() + 6)).unwrap();
    let d = &read.daily;
    assert_eq!(d.stations, names);
    assert_eq!(d.header()[0], "ux_AV15");
    assert_eq!(d.header().last().unwrap(), "date");
    // AKGG has a gap on day 6 (nearest: day 4), AV06's day-6 line is bad (nearest: day 5).
    let akgg = names.iter().position(|n| n == "AKGG").unwrap();
    let av06 = names.iter().position(|n| n == "AV06").unwrap();
    assert_eq!(d.reference[akgg], Some(day0() + 4));
    assert_eq!(d.reference[av06], Some(day0() + 5));
    assert_eq!(d.reference[12], None);
    assert_eq!(read.notes.len(), 3, "{:?}", read.notes);
    let s15 = 11; // AKUTAN index of AV15
    let v = d.rows[10][2 * 13]; // up of AV15 (column 0 of each block), day 10
    let want = u[10][24 + s15] - u[6][24 + s15];
    assert!((v - want).abs() <= READ_BACK_MAX_ERROR_MM, "{v} vs {want}");
    assert!(d
        .rows
        .iter()
        .all(|r| r[12].is_nan() && r[25].is_nan() && r[38].is_nan()));

    // Without a list: every file, by name.
    let read = tenv3::read_dir(&tmp.0, None, Reference::Auto).unwrap();
    let mut sorted: Vec<String> = synth::AKUTAN.iter().map(|s| s.0.to_string()).collect();
    sorted.sort();
    assert_eq!(read.daily.stations, sorted);
}
