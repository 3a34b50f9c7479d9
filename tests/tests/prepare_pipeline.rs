//! From NGL `tenv3` files to a trained model, through the real `magic` binary.
//!
//! The test writes the files of a 12-station network (the Akutan stations, placed around
//! 54.13° N, 165.97° W and written with unwrapped longitudes as NGL does) over nine years: a Mogi
//! source breathing under the network, a daily common mode, white and AR(1) noise, a linear trend
//! per station, 3 % random gaps per station, a step listed in an NGL steps file (both row shapes,
//! with entries for a station outside the network and one outside the data) and a 17 mm step
//! that is not listed. The same displacements without the trend and the listed step are laid out
//! by hand in the release layout. Then:
//!
//! 1. `magic prepare --detrend --steps` gives the stations' local coordinates, and the listed
//!    step and the trends are removed to within the noise, while the unlisted step is kept
//!    whole (MIDAS does not turn it into a ramp);
//! 2. the prepared folder has the hand-made one's layout (columns, dates of each split, source
//!    bounds), and `magic train` → `magic export` → `magic invert` on it gives the sources the
//!    same pipeline gives on the hand-made one (ΔV within the spread of a few epochs' training,
//!    both following the true ΔV), with the derived bounds in the model file;
//! 3. `magic loop` on the prepared folder traces the residuals to the unlisted step (station and
//!    day) and finds nothing else but the network's common mode and seasonal terms.

use magic_core::mogi::{self, Station, PARAM_NAMES};
use magic_tests::{magic_bin, TempDir};
use magic_train::gnss::geodesy::LocalFrame;
use magic_train::gnss::synth::{self, normal};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::path::Path;
use std::process::Command;

const N_DAYS: usize = 3300;
/// The periods (day indices): test first, then train, then valid, as in the release.
const TEST_DAYS: usize = 900;
const VALID_FROM: usize = 2800;
const ORIGIN: [f64; 2] = [54.13, -165.97];
const LISTED: (&str, usize, [f64; 3]) = ("AV06", 1300, [9.0, -7.0, 15.0]);
const UNLISTED: (&str, usize, [f64; 3]) = ("AV13", 1500, [17.0, -6.0, 0.0]);
const GAP_SHARE: f64 = 0.03;
const MJD_1970: i64 = 40_587;
const MONTHS: [&str; 12] = [
    "JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV", "DEC",
];
const HEADER: &str = "site YYMMMDD yyyy.yyyy __MJD week d reflon _e0(m) __east(m) ____n0(m) _north(m) u0(m) ____up(m) _ant(m) sig_e(m) sig_n(m) sig_u(m) __corr_en __corr_eu __corr_nu _latitude(deg) _longitude(deg) __height(m)";
/// White noise per component (mm).
const SIGMA_WHITE: [f64; 3] = [1.2, 1.2, 3.5];
/// Innovations of the AR(1) noise per component (mm) and its coefficient.
const SIGMA_AR: [f64; 3] = [0.15, 0.15, 0.4];
const AR_PHI: f64 = 0.995;
/// The network's daily common mode per component (mm).
const SIGMA_CM: [f64; 3] = [0.8, 0.8, 2.0];

/// A channel's noise (mm): white, AR(1) (stationary σ = innovation / √(1 − φ²)) and common mode.
fn sigma_noise(k: usize) -> f64 {
    (SIGMA_WHITE[k].powi(2) + SIGMA_AR[k].powi(2) / (1.0 - AR_PHI * AR_PHI) + SIGMA_CM[k].powi(2))
        .sqrt()
}

fn day0() -> i64 {
    magic_core::time::days_from_civil(2010, 1, 1)
}

fn date(t: usize, sep: char) -> String {
    let (y, m, d) = magic_core::time::civil_from_days(day0() + t as i64);
    format!("{y:04}{sep}{m:02}{sep}{d:02}")
}

fn yymmmdd(t: usize) -> String {
    let (y, m, d) = magic_core::time::civil_from_days(day0() + t as i64);
    format!("{:02}{}{:02}", y % 100, MONTHS[m as usize - 1], d)
}

fn stations() -> Vec<Station> {
    synth::AKUTAN
        .iter()
        .map(|s| Station {
            x_km: s.1,
            y_km: s.2,
            z_km: s.3,
        })
        .collect()
}

/// Volume change (10⁶ m³) on day t: inflation–deflation episodes that return to zero, so that
/// the source adds no long-term trend of its own.
fn volume(t: f64) -> f64 {
    [
        (420.0, 160.0, 6.0),
        (1250.0, 120.0, 3.0),
        (1950.0, 140.0, -2.5),
        (2500.0, 180.0, 4.0),
    ]
    .iter()
    .map(|&(c, w, peak)| {
        let u = (t - c) / w;
        if u.abs() < 1.0 {
            peak * 0.5 * (1.0 + (std::f64::consts::PI * u).cos())
        } else {
            0.0
        }
    })
    .sum()
}

/// The data: `truth[t][c]` (mm, NaN on a gap) without trend and listed step, and the trends.
struct Network {
    truth: Vec<Vec<f64>>,
    velocity: Vec<[f64; 3]>,
}

fn simulate(seed: u64) -> Network {
    let mut rng = StdRng::seed_from_u64(seed);
    let st = stations();
    let ns = st.len();
    let names: Vec<&str> = synth::AKUTAN.iter().map(|s| s.0).collect();
    let unlisted = names.iter().position(|n| *n == UNLISTED.0).unwrap();
    let mut ar = vec![0.0; 3 * ns];
    let mut u = vec![0.0; 3 * ns];
    let mut truth = vec![vec![0.0; 3 * ns]; N_DAYS];
    for (t, row) in truth.iter_mut().enumerate() {
        mogi::field(
            &st,
            &[
                synth::SOURCE[0],
                synth::SOURCE[1],
                synth::SOURCE[2],
                volume(t as f64),
            ],
            &mut u,
        )
        .unwrap();
        let cm: [f64; 3] = std::array::from_fn(|k| SIGMA_CM[k] * normal(&mut rng));
        for c in 0..3 * ns {
            let k = c / ns;
            ar[c] = AR_PHI * ar[c] + SIGMA_AR[k] * normal(&mut rng);
            row[c] = u[c] + cm[k] + ar[c] + SIGMA_WHITE[k] * normal(&mut rng);
            if c % ns == unlisted && t >= UNLISTED.1 {
                row[c] += UNLISTED.2[k];
            }
        }
        for s in 0..ns {
            if rng.random::<f64>() < GAP_SHARE {
                for k in 0..3 {
                    row[k * ns + s] = f64::NAN;
                }
            }
        }
    }
    let velocity = (0..ns)
        .map(|_| {
            [
                rng.random_range(-10.0..10.0),
                rng.random_range(5.0..25.0),
                rng.random_range(-4.0..4.0),
            ]
        })
        .collect();
    Network { truth, velocity }
}

/// One tenv3 line: station `s` on day `t` with displacement `d` (mm) and position `geo`.
fn tenv3_line(
    name: &str,
    s: usize,
    t: usize,
    d: [f64; 3],
    geo: [f64; 3],
    lon_shift: f64,
) -> String {
    let day = day0() + t as i64;
    let mjd = day + MJD_1970;
    let int = [
        -7000 - 500 * s as i64,
        6_000_000 + 1000 * s as i64,
        300 + 10 * s as i64,
    ];
    let frac: [f64; 3] = std::array::from_fn(|k| 0.25 + d[k] / 1000.0);
    format!(
        "{name} {} {:.4} {mjd} {} {} -166 {} {:.6} {} {:.6} {} {:.6} 0.0000 0.001100 0.001200 0.004500 0.0123 -0.0204 0.0071 {:.7} {:.7} {:.4}",
        yymmmdd(t),
        2010.0 + t as f64 / 365.25,
        (mjd - 44_244) / 7,
        (mjd - 44_244) % 7,
        int[0],
        frac[0],
        int[1],
        frac[1],
        int[2],
        frac[2],
        geo[0],
        geo[1] + lon_shift,
        geo[2]
    )
}

/// Writes the station files and the steps file.
fn write_tenv3(dir: &Path, net: &Network) {
    let frame = LocalFrame::new(ORIGIN[0], ORIGIN[1], 0.0);
    let ns = synth::AKUTAN.len();
    for (s, sta) in synth::AKUTAN.iter().enumerate() {
        let geo = frame.geodetic([sta.1 * 1000.0, sta.2 * 1000.0, sta.3 * 1000.0]);
        // NGL does not wrap longitudes: some stations at −165.97°, some at 194.03°, some −525.97°.
        let lon_shift = [0.0, 360.0, -360.0][s % 3];
        let mut text = format!("{HEADER}\n");
        for t in 0..N_DAYS {
            let row = &net.truth[t];
            if row[s].is_nan() {
                continue;
            }
            let d: [f64; 3] = std::array::from_fn(|k| {
                let listed = if sta.0 == LISTED.0 && t >= LISTED.1 {
                    LISTED.2[k]
                } else {
                    0.0
                };
                row[k * ns + s] + net.velocity[s][k] * t as f64 / 365.25 + listed
            });
            text += &tenv3_line(sta.0, s, t, d, geo, lon_shift);
            text.push('\n');
        }
        std::fs::write(dir.join(format!("{}.tenv3", sta.0)), text).unwrap();
    }
}

fn steps_file(path: &Path) {
    let text = format!(
        "{0}  {1}  1  Antenna_Code_Changed\n\
         {0}  {1}  2  158.49  102.3  6.0  us{2}abcd\n\
         P999  {1}  2  50.12  20.0  5.0  ci12345\n\
         AKGG  09JUN01  1  Receiver_Firmware_Changed\n",
        LISTED.0,
        yymmmdd(LISTED.1),
        &date(LISTED.1, '-')[..4],
    );
    std::fs::write(path, text).unwrap();
}

/// The hand-made release layout of `net.truth` (NaN-aware standardisation on the training days).
fn write_hand_made(dir: &Path, net: &Network, margin_km: f64) {
    std::fs::create_dir_all(dir).unwrap();
    let ns = synth::AKUTAN.len();
    let names: Vec<&str> = synth::AKUTAN.iter().map(|s| s.0).collect();
    let nc = 3 * ns;
    let train = TEST_DAYS..VALID_FROM;
    // The convention of `magic prepare`: each channel relative to its median over the 30 days
    // from the first day on which every station has data.
    let r0 = (0..N_DAYS)
        .find(|&t| net.truth[t].iter().all(|v| v.is_finite()))
        .unwrap();
    let level: Vec<f64> = (0..nc)
        .map(|c| {
            let mut v: Vec<f64> = net.truth[r0..r0 + 30]
                .iter()
                .map(|r| r[c])
                .filter(|v| v.is_finite())
                .collect();
            median(&mut v)
        })
        .collect();
    let truth: Vec<Vec<f64>> = net
        .truth
        .iter()
        .map(|r| r.iter().zip(&level).map(|(v, l)| v - l).collect())
        .collect();
    let mut mean = vec![0.0; nc];
    let mut scale = vec![0.0; nc];
    for c in 0..nc {
        let v: Vec<f64> = train
            .clone()
            .map(|t| truth[t][c])
            .filter(|v| v.is_finite())
            .collect();
        mean[c] = v.iter().sum::<f64>() / v.len() as f64;
        scale[c] = (v.iter().map(|x| (x - mean[c]).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
    }
    let mut header: Vec<String> = vec![];
    for comp in ["ux", "uy", "uz"] {
        header.extend(names.iter().map(|n| format!("{comp}_{n}")));
    }
    header.push("date".into());
    for (name, range) in [
        ("test", 0..TEST_DAYS),
        ("train", train),
        ("valid", VALID_FROM..N_DAYS),
    ] {
        let mut text = header.join(",") + "\n";
        for t in range {
            let v: Vec<String> = (0..nc)
                .map(|c| ((truth[t][c] - mean[c]) / scale[c]) as f32)
                .map(|v| v.to_string())
                .collect();
            text += &format!("{},{}\n", v.join(","), date(t, '.'));
        }
        std::fs::write(dir.join(format!("{name}.csv")), text).unwrap();
    }
    let lines = |v: &[f64]| v.iter().map(|x| format!("{x}\n")).collect::<String>();
    std::fs::write(dir.join("train_x_mean.csv"), lines(&mean)).unwrap();
    std::fs::write(dir.join("train_x_scale.csv"), lines(&scale)).unwrap();
    let mut st = serde_json::Map::new();
    for s in synth::AKUTAN {
        st.insert(
            s.0.into(),
            serde_json::json!({"xE": s.1, "yN": s.2, "zV": s.3}),
        );
    }
    std::fs::write(
        dir.join("stations.json"),
        serde_json::to_string(&st).unwrap(),
    )
    .unwrap();
    let span = |k: usize| {
        let v: Vec<f64> = synth::AKUTAN
            .iter()
            .map(|s| if k == 0 { s.1 } else { s.2 })
            .collect();
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        [lo - margin_km, hi + margin_km]
    };
    let bounds = serde_json::json!({
        "x_km": span(0), "y_km": span(1),
        "depth_km": [2.0, 20.0], "dv_1e6m3": [-10.0, 10.0],
    });
    std::fs::write(dir.join("bounds.json"), bounds.to_string()).unwrap();
}

fn magic(args: &[&str]) -> String {
    let started = std::time::Instant::now();
    let out = Command::new(magic_bin())
        .args(args)
        .output()
        .expect("magic runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "magic {}: {stderr}", args.join(" "));
    eprintln!(
        "magic {}: {:.1} s",
        args[0],
        started.elapsed().as_secs_f64()
    );
    stderr
}

/// A CSV of numbers (the header and any `date` column dropped): rows of values.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut rdr = csv::Reader::from_path(path).unwrap();
    let header: Vec<String> = rdr.headers().unwrap().iter().map(String::from).collect();
    let rows = rdr
        .records()
        .map(|r| {
            r.unwrap()
                .iter()
                .zip(&header)
                .filter(|(_, h)| !h.contains("date") && *h != "flags")
                .map(|(v, _)| v.parse::<f64>().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    (header, rows)
}

fn read_vec(path: &Path) -> Vec<f64> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.trim().parse().unwrap())
        .collect()
}

/// Physical displacements (mm) of the three splits of a layout, in time order.
fn physical(dir: &Path) -> Vec<Vec<f64>> {
    let mean = read_vec(&dir.join("train_x_mean.csv"));
    let scale = read_vec(&dir.join("train_x_scale.csv"));
    let mut out = vec![];
    for split in ["test", "train", "valid"] {
        let (_, rows) = read_csv(&dir.join(format!("{split}.csv")));
        for r in rows {
            out.push(
                r.iter()
                    .take(mean.len())
                    .enumerate()
                    .map(|(c, v)| v * scale[c] + mean[c])
                    .collect(),
            );
        }
    }
    out
}

/// Pearson correlation of two series.
fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ab += (x - ma) * (y - mb);
        aa += (x - ma) * (x - ma);
        bb += (y - mb) * (y - mb);
    }
    ab / (aa * bb).sqrt()
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// How far the prepared displacements are from the truth after a constant per channel (the
/// reference epoch): (rms, worst |·|) per component over channels and days, mm.
fn departure(prep: &[Vec<f64>], truth: &[Vec<f64>]) -> [[f64; 2]; 3] {
    let ns = synth::AKUTAN.len();
    let mut out = [[0.0f64; 2]; 3];
    let mut counts = [0usize; 3];
    for c in 0..3 * ns {
        let mut d: Vec<f64> = (0..N_DAYS)
            .map(|t| prep[t][c] - truth[t][c])
            .filter(|v| v.is_finite())
            .collect();
        let m = median(&mut d.clone());
        for v in d.iter_mut() {
            *v -= m;
        }
        let k = c / ns;
        let rms = (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt();
        eprintln!("channel {c}: departure rms {rms:.2} mm");
        for v in &d {
            out[k][0] += v * v;
            out[k][1] = out[k][1].max(v.abs());
        }
        counts[k] += d.len();
    }
    for k in 0..3 {
        out[k][0] = (out[k][0] / counts[k] as f64).sqrt();
    }
    out
}

/// The departure (rms over channels and days) of the prepared displacements from the truth, in
/// units of the channels' noise σ ([`sigma_noise`]; the AR(1) part, a slow wander of 1.5 mm
/// (4 mm up) over ~200 days, is what limits any trend estimate over nine years): measured 0.49
/// (east), 0.33 (north), 0.27 (up) for the simulation seed used here, at most 0.62, 0.40, 0.36
/// over seeds 11–14; required ≤ 0.75.
const DEPARTURE_RMS_NOISE: f64 = 0.75;
/// The largest single departure, in noise σ: measured 1.84 (east), 1.39, 0.98 here, at most 2.26,
/// 1.39, 1.46 over seeds 11–14; required ≤ 2.5.
const DEPARTURE_MAX_NOISE: f64 = 2.5;

#[test]
fn tenv3_files_to_a_trained_model_and_the_unlisted_step() {
    let tmp = TempDir::new("prepare");
    let net = simulate(11);
    let files = tmp.join("tenv3");
    std::fs::create_dir_all(&files).unwrap();
    write_tenv3(&files, &net);
    let steps = tmp.join("steps.txt");
    steps_file(&steps);
    let prep = tmp.join("prepared");
    let hand = tmp.join("hand");
    write_hand_made(&hand, &net, 2.0);
    let test = format!("{}..{}", date(0, '-'), date(TEST_DAYS - 1, '-'));
    let valid = format!("{}..{}", date(VALID_FROM, '-'), date(N_DAYS - 1, '-'));
    let origin = format!("{},{}", ORIGIN[0], ORIGIN[1]);
    let log = magic(&[
        "prepare",
        "--tenv3",
        files.to_str().unwrap(),
        "--out",
        prep.to_str().unwrap(),
        "--steps",
        steps.to_str().unwrap(),
        "--detrend",
        "--test",
        &test,
        "--valid",
        &valid,
        "--origin",
        &origin,
    ]);
    eprintln!("{log}");

    // Coordinates: the stations where they were put (the files' 7 decimals of a degree: ~1 cm).
    let st: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(prep.join("stations.json")).unwrap())
            .unwrap();
    for s in synth::AKUTAN {
        for (key, want) in [("xE", s.1), ("yN", s.2), ("zV", s.3)] {
            let got = st[s.0][key].as_f64().unwrap();
            assert!((got - want).abs() < 1e-4, "{} {key}: {got} vs {want}", s.0);
        }
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(prep.join("prepare.json")).unwrap()).unwrap();
    assert_eq!(
        report["steps_other_stations"], 1,
        "P999 is not in the network"
    );
    let stations = report["stations"].as_array().unwrap();
    for (s, sta) in stations.iter().enumerate() {
        // Trends within 3 standard errors (the AR(1) noise makes MIDAS's errors realistic).
        for k in 0..3 {
            let v = sta["velocity_mm_yr"][k].as_array().unwrap();
            let (got, se) = (v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
            eprintln!(
                "{} {k}: MIDAS {got:.2} ± {se:.2}, true {:.2}, error {:.2}",
                sta["name"],
                net.velocity[s][k],
                got - net.velocity[s][k]
            );
            assert!(
                (got - net.velocity[s][k]).abs() < 3.0 * se.max(0.1),
                "{} {k}: {got} ± {se} vs {}",
                sta["name"],
                net.velocity[s][k]
            );
        }
        let steps = sta["steps"].as_array().unwrap();
        if sta["name"] == LISTED.0 {
            assert_eq!(steps.len(), 1, "two entries on one day are one step");
            assert_eq!(steps[0]["date"], date(LISTED.1, '-'));
        } else {
            assert!(steps.is_empty(), "{}", sta["name"]);
        }
    }
    assert!(
        log.contains("AKGG: step on 2009-06-01 is outside its data"),
        "{log}"
    );

    // The trend and the listed step removed to within the noise; nothing else changed.
    let p = physical(&prep);
    let h = physical(&hand);
    assert_eq!(p.len(), N_DAYS);
    let dep = departure(&p, &net.truth);
    eprintln!(
        "departure from the truth (rms, max mm) E {:?} N {:?} U {:?}",
        dep[0], dep[1], dep[2]
    );
    for (k, dep) in dep.iter().enumerate() {
        eprintln!(
            "component {k}: departure rms {:.2} σ, max {:.2} σ (σ = {:.2} mm)",
            dep[0] / sigma_noise(k),
            dep[1] / sigma_noise(k),
            sigma_noise(k)
        );
        assert!(
            dep[0] < DEPARTURE_RMS_NOISE * sigma_noise(k),
            "{k}: {dep:?}"
        );
        assert!(
            dep[1] < DEPARTURE_MAX_NOISE * sigma_noise(k),
            "{k}: {dep:?}"
        );
    }
    // Gaps stay gaps, one row per day.
    for t in 0..N_DAYS {
        for c in 0..36 {
            assert_eq!(
                p[t][c].is_nan(),
                net.truth[t][c].is_nan(),
                "day {t} channel {c}"
            );
            assert_eq!(h[t][c].is_nan(), net.truth[t][c].is_nan());
        }
    }
    // The unlisted step is still a step of its full size (not a ramp).
    let s13 = synth::AKUTAN
        .iter()
        .position(|s| s.0 == UNLISTED.0)
        .unwrap();
    let mean = |a: usize, b: usize| {
        let v: Vec<f64> = (a..b)
            .map(|t| p[t][s13])
            .filter(|v| v.is_finite())
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    let jump = mean(UNLISTED.1, UNLISTED.1 + 60) - mean(UNLISTED.1 - 60, UNLISTED.1);
    eprintln!(
        "unlisted step in the prepared east of {}: {jump:.2} mm (injected {})",
        UNLISTED.0, UNLISTED.2[0]
    );
    assert!((jump - UNLISTED.2[0]).abs() < 2.0, "{jump}");

    // The same layout as the hand-made one: columns, dates per split, source bounds.
    for split in ["train", "valid", "test"] {
        let read = |d: &Path| std::fs::read_to_string(d.join(format!("{split}.csv"))).unwrap();
        let (a, b) = (read(&prep), read(&hand));
        // The channels and the date (prepare also writes the date's `sin_date`, `cos_date`).
        let head = |t: &str| {
            t.lines()
                .next()
                .unwrap()
                .split(',')
                .take(37)
                .collect::<Vec<_>>()
                .join(",")
        };
        assert_eq!(head(&a), head(&b), "{split}: columns");
        let dates = |t: &str| {
            t.lines()
                .skip(1)
                .map(|l| l.split(',').nth(36).unwrap().to_string())
                .collect::<Vec<_>>()
        };
        assert_eq!(dates(&a), dates(&b), "{split}: dates");
    }
    let bounds = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("bounds.json")).unwrap()).unwrap()
    };
    let (bp, bh) = (bounds(&prep), bounds(&hand));
    for name in PARAM_NAMES {
        for k in 0..2 {
            let (x, y) = (bp[name][k].as_f64().unwrap(), bh[name][k].as_f64().unwrap());
            assert!((x - y).abs() < 1e-4, "bounds {name}: {x} vs {y}");
        }
    }

    // prepare → train → export → invert, against the hand-made layout.
    let mut results = vec![];
    for (tag, dir) in [("prepared", &prep), ("hand", &hand)] {
        let f32m = tmp.join(&format!("{tag}_B.magic"));
        let int8 = tmp.join(&format!("{tag}_B_int8.magic"));
        let out = tmp.join(&format!("{tag}_inv.csv"));
        let d = dir.to_str().unwrap();
        magic(&[
            "train",
            "mogi",
            "--variant",
            "B",
            "--epochs",
            PIPELINE_EPOCHS,
            "--seed",
            "1",
            "--data-dir",
            d,
            "--out",
            f32m.to_str().unwrap(),
        ]);
        magic(&[
            "export",
            "--model",
            f32m.to_str().unwrap(),
            "--data-dir",
            d,
            "--out",
            int8.to_str().unwrap(),
        ]);
        magic(&[
            "invert",
            "--model",
            int8.to_str().unwrap(),
            "--input",
            dir.join("test.csv").to_str().unwrap(),
            "--standardized",
            "--output",
            out.to_str().unwrap(),
        ]);
        // The model file carries the derived source bounds.
        let bytes = std::fs::read(&int8).unwrap();
        let m = magic_core::Model::decode(&bytes).unwrap();
        for (j, name) in PARAM_NAMES.iter().enumerate() {
            for k in 0..2 {
                let want = bp[*name][k].as_f64().unwrap();
                assert!(
                    (m.bounds[j][k] as f64 - want).abs() < 1e-4,
                    "{tag} model bounds of {name}: {:?} vs {want}",
                    m.bounds[j]
                );
            }
        }
        results.push(read_csv(&out));
    }
    let (header, a) = &results[0];
    let (_, b) = &results[1];
    assert_eq!(a.len(), TEST_DAYS);
    assert_eq!(b.len(), TEST_DAYS);
    assert!(header.iter().any(|h| h == PARAM_NAMES[0]));
    // The sources stay inside the bounds; both pipelines follow the true ΔV alike, and their
    // sources agree.
    let mut mean_abs = [0.0f64; 4];
    for (ra, rb) in a.iter().zip(b) {
        for j in 0..4 {
            let lo = bh[PARAM_NAMES[j]][0].as_f64().unwrap();
            let hi = bh[PARAM_NAMES[j]][1].as_f64().unwrap();
            for v in [ra[j], rb[j]] {
                assert!(v >= lo - 1e-6 && v <= hi + 1e-6, "{}: {v}", PARAM_NAMES[j]);
            }
            mean_abs[j] += (ra[j] - rb[j]).abs() / TEST_DAYS as f64;
        }
    }
    let true_dv: Vec<f64> = (0..TEST_DAYS).map(|t| volume(t as f64)).collect();
    let dv = |r: &[Vec<f64>]| r.iter().map(|v| v[3]).collect::<Vec<f64>>();
    let (corr_p, corr_h) = (correlation(&dv(a), &true_dv), correlation(&dv(b), &true_dv));
    eprintln!(
        "test split: mean |prepared − hand-made| x {:.3} km, y {:.3} km, depth {:.3} km, ΔV {:.3}·10⁶ m³; correlation of ΔV with the truth: prepared {corr_p:.3}, hand-made {corr_h:.3}",
        mean_abs[0], mean_abs[1], mean_abs[2], mean_abs[3]
    );
    assert!(corr_p > DV_CORRELATION_MIN, "prepared: {corr_p}");
    assert!(corr_h > DV_CORRELATION_MIN, "hand-made: {corr_h}");
    assert!(mean_abs[3] < PIPELINE_DV_DIFFERENCE, "ΔV: {}", mean_abs[3]);

    // `magic loop` on the prepared data: the unlisted step (station and day), and nothing else
    // but the network's common mode and seasonal terms.
    let report = tmp.join("loop");
    magic(&[
        "loop",
        "mogi",
        "--data-dir",
        prep.to_str().unwrap(),
        "--epochs",
        LOOP_EPOCHS,
        "--rounds",
        "3",
        "--surrogates",
        LOOP_SURROGATES,
        "--no-classical",
        "--report",
        report.to_str().unwrap(),
    ]);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("report.json")).unwrap())
            .unwrap();
    let lp = &r["loop"];
    let rounds = lp["rounds"].as_array().unwrap();
    for round in rounds {
        for c in round["candidates"].as_array().unwrap() {
            if c["significant"] == true {
                eprintln!(
                    "round {}: {} {} (explained {:.4}, chance {:.4})",
                    round["round"],
                    c["family"],
                    c["params"],
                    c["variance_explained"],
                    c["chance_level"]
                );
            }
        }
    }
    eprintln!("loop stopped: {}", lp["stop"]);
    // What the loop added to F and kept: the step, on its station and day (and at most the
    // network's common mode and seasonal terms).
    let added: Vec<&serde_json::Value> = rounds
        .iter()
        .filter(|r| r["kept"] == true)
        .filter_map(|r| r.get("added").filter(|a| !a.is_null()))
        .collect();
    let mut steps = 0;
    for a in &added {
        let family = a["family"].as_str().unwrap();
        assert!(
            ["common_mode", "seasonal", "step"].contains(&family),
            "the loop added {family}: {a}"
        );
        if family == "step" {
            let epoch = a["params"]["epoch"].as_str().unwrap();
            let day = magic_train::gnss::tenv3::parse_ymd(epoch).unwrap() - day0();
            assert_eq!(a["params"]["station"], UNLISTED.0, "{a}");
            assert!(
                (day - UNLISTED.1 as i64).abs() <= STEP_DAY_TOLERANCE,
                "step on {epoch}, injected on {}",
                date(UNLISTED.1, '-')
            );
            steps += 1;
        }
    }
    assert_eq!(steps, 1, "the unlisted step, once: {}", lp["stop"]);
    // With them in F, nothing else is left that beats chance.
    let last = rounds.iter().rev().find(|r| r["kept"] == true).unwrap();
    for c in last["candidates"].as_array().unwrap() {
        let family = c["family"].as_str().unwrap();
        assert!(
            c["significant"] != true || ["common_mode", "seasonal"].contains(&family),
            "after round {}: {family} still found: {c}",
            last["round"]
        );
    }
}

/// Epochs of the B models trained on the prepared and the hand-made layouts. B: the source is
/// F's alone (a C model's correction may absorb it, and at a few epochs here mirrors ΔV).
const PIPELINE_EPOCHS: &str = "10";
/// Correlation of the inverted ΔV with the true one on the test days (training seed 1): measured
/// 0.879 (prepared) and 0.935 (hand-made) here; over simulation seeds 11–14 0.776–0.901
/// (prepared) and 0.820–0.935 (hand-made); required above 0.7.
const DV_CORRELATION_MIN: f64 = 0.7;
/// Mean |ΔV prepared − ΔV hand-made| on the test days (10⁶ m³, range ±10): measured 0.77 here
/// (0.66 with training seed 2; two training seeds on the same hand-made layout differ by 0.28),
/// 0.30–0.77 over simulation seeds 11–14; required below 1.2.
const PIPELINE_DV_DIFFERENCE: f64 = 1.2;

/// Epochs per training in the loop, and surrogates per family.
const LOOP_EPOCHS: &str = "10";
const LOOP_SURROGATES: &str = "10";

/// How far (days) the found step's epoch may be from the injected one (measured: on the day).
const STEP_DAY_TOLERANCE: i64 = 3;
