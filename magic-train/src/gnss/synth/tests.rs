//! Properties of the generator: the original generator unchanged, standardisation,
//! repeatability, and a truth that states what was injected.

use super::inject::second_source::{
    course, network_box, MIN_RESOLVABLE, MIN_RESOLVABLE_NEAR, MIN_VISIBLE_MM,
    UNDER_STATION_APART_KM, UNDER_STATION_MM,
};
use super::truth::{background, injected, Injected};
use super::*;
use crate::data::Dataset;

const SPLITS: [SplitName; 3] = [SplitName::Test, SplitName::Train, SplitName::Valid];

/// The record in mm, in time order (rows of test, train, valid), from the standardised data.
fn mm(d: &Dataset) -> Vec<Vec<f64>> {
    [&d.test, &d.train, &d.valid]
        .iter()
        .flat_map(|s| s.x.iter())
        .map(|r| {
            r.iter()
                .enumerate()
                .map(|(c, v)| *v as f64 * d.scale[c] + d.mean[c])
                .collect()
        })
        .collect()
}

/// What `spec` adds to the clean data of its seed and noise model (mm, per day and channel).
fn added(spec: Spec) -> (Vec<Vec<f64>>, serde_json::Value) {
    let s = spec.generate();
    let clean = Spec {
        scenario: Scenario::Clean,
        ..spec
    }
    .generate();
    let (a, b) = (mm(&s.problem.data), mm(&clean.problem.data));
    let diff = a
        .iter()
        .zip(&b)
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| p - q).collect())
        .collect();
    (diff, s.truth)
}

/// Storage of the standardised values in f32 and the destandardisation: the largest error of
/// a difference of two datasets in mm (values of at most ~100 mm, relative error 6e-8).
const MM_TOL: f64 = 1e-4;

fn fnv(h: u64, bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(h, |h, b| (h ^ *b as u64).wrapping_mul(0x100_0000_01b3))
}

/// FNV-1a of a dataset's values, dates and standardisation, and of its truth's `effect` (without
/// the `shape` a second source now also states).
fn fingerprint(s: &Synthetic) -> (u64, u64) {
    let d = &s.problem.data;
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for sp in [&d.train, &d.valid, &d.test] {
        for r in &sp.x {
            for v in r {
                h = fnv(h, &v.to_bits().to_le_bytes());
            }
        }
        for t in &sp.dates {
            h = fnv(h, t.as_bytes());
        }
    }
    for v in d.mean.iter().chain(&d.scale) {
        h = fnv(h, &v.to_bits().to_le_bytes());
    }
    let mut e = s.truth["effect"].clone();
    if let Some(m) = e.get_mut("params").and_then(|p| p.as_object_mut()) {
        m.remove("shape");
    }
    (h, fnv(0xcbf2_9ce4_8422_2325u64, e.to_string().as_bytes()))
}

#[test]
fn the_paper_generator_is_unchanged() {
    // Fingerprints of the generator as it was before scenarios, placements and noise models
    // were added (seeds 1, 2, 7 of every original scenario): the same bits. (The truth's second
    // fingerprint changed where its definition did: common_mode's and elevation's RMS are stated
    // over the whole record, not the training period; the data's bits are as before.)
    let want: [(&str, [(u64, u64); 3]); 7] = [
        (
            "clean",
            [
                (0x0cc750691df4ddd5, 0x5b9bc4ba528108e4),
                (0x7f1ee8b961baffd8, 0x5b9bc4ba528108e4),
                (0x15bcea10adf90268, 0x5b9bc4ba528108e4),
            ],
        ),
        (
            "common_mode",
            [
                (0xb72b4127e047dbd9, 0x26da408a18bd9015),
                (0x67007f7c14936b17, 0xd1d98885ec75e45a),
                (0xcc0d03548e79807d, 0x330c47b81abe1530),
            ],
        ),
        (
            "seasonal",
            [
                (0x1d82e8e0870b8176, 0xe2c209db8df77fbd),
                (0x61ebc40511baa8b9, 0x21d66125f06763e2),
                (0x706ef97b2f4ef816, 0x239baaa47df8e3b9),
            ],
        ),
        (
            "elevation",
            [
                (0xc87c8e68a5698cee, 0x2b9de70654f17bdf),
                (0x582e5b4004aa1545, 0x70ebdaef0623b3f8),
                (0x16326bb0bc38bb5c, 0x70d4c22aa608ab5f),
            ],
        ),
        (
            "step",
            [
                (0x0d4b34ac20fbbca7, 0x359ea82e224fb85a),
                (0x71f06d8ede74635d, 0xd67c843a7c7b3946),
                (0xf0752d4810449b85, 0x9f9c435a428cf550),
            ],
        ),
        (
            "second_source",
            [
                (0x9a1ddc7962c3db05, 0x76d0594c2a97d6b5),
                (0xa5786058ee8022c0, 0xc599104d3fe30b8e),
                (0xaae9171f8df16ab2, 0x698e271c1d575997),
            ],
        ),
        (
            "drift",
            [
                (0xdc6221987eef0fed, 0xb0bf776c090736d7),
                (0x5b323d59957d1a1a, 0xdd9eb5995e5bd6a6),
                (0x505246c2b5cd4483, 0x95c882cd1082ac77),
            ],
        ),
    ];
    for (name, fps) in want {
        for (seed, fp) in [1u64, 2, 7].into_iter().zip(fps) {
            let s = generate(Scenario::parse(name).unwrap(), seed);
            assert_eq!(fingerprint(&s), fp, "{name} seed {seed}");
        }
    }
}

#[test]
fn civil_dates() {
    assert_eq!(magic_core::time::civil_from_days(13_149), (2006, 1, 1));
    assert_eq!(crate::gnss::data::day_of_year("2008.03.01"), 61.0);
}

#[test]
fn datasets_are_standardised_and_repeatable() {
    for noise in NoiseModel::ALL {
        let spec = Spec::new(Scenario::SecondSourceStep, 3)
            .noise(noise)
            .placed(SplitName::Valid);
        let (a, b) = (spec.generate(), spec.generate());
        let d = &a.problem.data;
        assert_eq!(d.test.x[10], b.problem.data.test.x[10]);
        assert_eq!(a.truth, b.truth);
        let other = Spec { seed: 4, ..spec }.generate();
        assert_ne!(d.train.x[10], other.problem.data.train.x[10]);
        let n = d.train.len() as f64;
        for c in [0, 5, 35] {
            let m = d.train.x.iter().map(|r| r[c] as f64).sum::<f64>() / n;
            let v = d
                .train
                .x
                .iter()
                .map(|r| (r[c] as f64 - m).powi(2))
                .sum::<f64>()
                / n;
            assert!(
                m.abs() < 1e-5 && (v - 1.0).abs() < 1e-5,
                "{noise:?} {c}: {m} {v}"
            );
        }
        let layout = noise.layout();
        assert_eq!(d.test.len(), layout.periods[0]);
        assert_eq!(d.train.len(), layout.periods[1]);
        assert_eq!(d.valid.len(), layout.periods[2]);
        assert_eq!(d.test.dates[0], "2006.01.01");
        assert_eq!(a.dv.len(), layout.n_days());
    }
}

/// Two effects at once — of different kinds, or two extra sources — are the sum of each alone,
/// with the same parameters.
#[test]
fn two_effects_are_the_sum_of_each_alone() {
    let pairs = [
        (
            Scenario::StepElevation,
            [Scenario::Step, Scenario::Elevation],
        ),
        (
            Scenario::TwoSources,
            [Scenario::SecondSource, Scenario::LastingDeflationFar],
        ),
    ];
    for noise in NoiseModel::ALL {
        for (sc, [one, other]) in pairs {
            let spec = Spec::new(sc, 2).noise(noise).placed(SplitName::Valid);
            let (both, t) = added(spec);
            let (a, ta) = added(Spec {
                scenario: one,
                ..spec
            });
            let (b, tb) = added(Spec {
                scenario: other,
                ..spec
            });
            assert_eq!(injected(&t), [injected(&ta), injected(&tb)].concat());
            assert!(
                t.get("effect").is_none(),
                "a single `effect` only for one effect"
            );
            for (t, row) in both.iter().enumerate() {
                for c in 0..row.len() {
                    let e = row[c] - a[t][c] - b[t][c];
                    assert!(
                        e.abs() < 3.0 * MM_TOL,
                        "{noise:?} {} day {t} channel {c}: {e}",
                        sc.name()
                    );
                }
            }
        }
    }
}

fn date_row(layout: &Layout, date: &serde_json::Value) -> usize {
    let d = magic_core::time::parse_date(date.as_str().unwrap()).unwrap();
    layout.row(d).unwrap()
}

fn in_period(layout: &Layout, placement: SplitName, t: usize) -> bool {
    let (a, b) = layout.range(placement);
    a <= t && t < b
}

/// Every injected step is at its station from its epoch on, nowhere else; `step+step` holds
/// `step`'s and another at another station.
#[test]
fn a_step_is_where_and_when_the_truth_says() {
    for noise in NoiseModel::ALL {
        for placement in SPLITS {
            for seed in [5, 6] {
                let spec = Spec::new(Scenario::TwoSteps, seed)
                    .noise(noise)
                    .placed(placement);
                let (diff, truth) = added(spec);
                let (_, one) = added(Spec {
                    scenario: Scenario::Step,
                    ..spec
                });
                let steps = injected(&truth);
                assert_eq!(steps.len(), 2);
                assert_eq!(steps[0], injected(&one)[0]);
                assert_ne!(steps[0].params["station"], steps[1].params["station"]);
                let layout = noise.layout();
                let mut want = vec![vec![0.0; diff[0].len()]; diff.len()];
                for p in steps.iter().map(|s| &s.params) {
                    let e = date_row(&layout, &p["epoch"]);
                    assert!(in_period(&layout, placement, e), "{noise:?} {placement}");
                    let i = AKUTAN.iter().position(|s| s.0 == p["station"]).unwrap();
                    for row in &mut want[e..] {
                        for k in 0..3 {
                            row[k * 12 + i] += p["offset_mm"][k].as_f64().unwrap();
                        }
                    }
                }
                for (t, (row, w)) in diff.iter().zip(&want).enumerate() {
                    for (c, (v, w)) in row.iter().zip(w).enumerate() {
                        // The offsets are stated to three decimals.
                        assert!((v - w).abs() < 1.2e-3, "day {t} channel {c}: {v} vs {w}");
                    }
                }
            }
        }
    }
}

/// A source under a station: within 1 km of a station far enough from the main source,
/// 1.5–2.5 km deep, moving that station by the stated range at its final volume, from a start
/// in the placement's period.
#[test]
fn a_source_under_a_station_moves_that_station_most() {
    let network = Network::akutan();
    let ns = network.len();
    for noise in NoiseModel::ALL {
        for placement in SPLITS {
            let spec = Spec::new(Scenario::LastingDeflationUnderStation, 4)
                .noise(noise)
                .placed(placement);
            let truth = spec.generate().truth;
            let p = &injected(&truth)[0].params;
            let what = format!("{noise:?} {placement}");
            let num = |k: &str| p[k].as_f64().unwrap();
            let pos = [num("x_km"), num("y_km"), num("depth_km")];
            let near = |s: &magic_core::mogi::Station| (s.x_km - pos[0]).hypot(s.y_km - pos[1]);
            let (i, st) = (network.stations.iter().enumerate())
                .min_by(|a, b| near(a.1).total_cmp(&near(b.1)))
                .unwrap();
            assert!(
                near(st) <= 1.0,
                "{what}: {} km from {}",
                near(st),
                network.names[i]
            );
            let apart = (st.x_km - SOURCE[0]).hypot(st.y_km - SOURCE[1]);
            assert!(apart >= UNDER_STATION_APART_KM, "{what}: {apart} km");
            assert!((1.5..=2.5).contains(&pos[2]), "{what}: {} km deep", pos[2]);
            let mut u = vec![0.0; 3 * ns];
            let dv = num("peak_dv_1e6m3");
            magic_core::mogi::field(&network.stations, &[pos[0], pos[1], pos[2], dv], &mut u)
                .unwrap();
            let norm = |j: usize| (0..3).map(|k| u[k * ns + j].powi(2)).sum::<f64>().sqrt();
            let most = (0..ns).map(norm).fold(0.0, f64::max);
            // The peak ΔV is stated to four decimals.
            let [lo, hi] = UNDER_STATION_MM;
            assert!(
                dv < 0.0 && most >= lo - 0.1 && most <= hi + 0.1,
                "{what}: {most} mm"
            );
            let layout = noise.layout();
            assert!(in_period(
                &layout,
                placement,
                date_row(&layout, &p["start"])
            ));
        }
    }
}

#[test]
fn a_second_source_is_where_and_when_the_truth_says() {
    let network = Network::akutan();
    let bx = network_box(&network.stations, 2.0);
    // Scenario, distance from the main source (km), depth (km), resolvable share.
    let kinds = [
        (
            Scenario::SecondSource,
            [5.0, 99.0],
            [4.0, 8.0],
            MIN_RESOLVABLE,
        ),
        (
            Scenario::SecondSourceNear,
            [2.0, 4.0],
            [3.0, 4.0],
            MIN_RESOLVABLE_NEAR,
        ),
        (
            Scenario::SecondSourceFar,
            [6.0, 12.0],
            [4.0, 8.0],
            MIN_RESOLVABLE,
        ),
        (
            Scenario::LastingDeflationNear,
            [2.0, 4.0],
            [3.0, 4.0],
            MIN_RESOLVABLE_NEAR,
        ),
        (
            Scenario::LastingDeflationFar,
            [6.0, 12.0],
            [3.0, 4.0],
            MIN_RESOLVABLE,
        ),
    ];
    for noise in NoiseModel::ALL {
        for placement in SPLITS {
            for (sc, [lo, hi], [d0, d1], min_res) in kinds {
                let spec = Spec::new(sc, 6).noise(noise).placed(placement);
                let (diff, truth) = added(spec);
                let p = &injected(&truth)[0].params;
                let what = format!("{} {noise:?} {placement}", sc.name());
                let num = |k: &str| p[k].as_f64().unwrap();
                let pos = [num("x_km"), num("y_km"), num("depth_km")];
                let r = (pos[0] - SOURCE[0]).hypot(pos[1] - SOURCE[1]);
                assert!(r >= lo && r <= hi, "{what}: {r} km from the main source");
                assert!(pos[2] >= d0 && pos[2] <= d1, "{what}: {} km deep", pos[2]);
                assert!(pos[0] >= bx[0] && pos[0] <= bx[1] && pos[1] >= bx[2] && pos[1] <= bx[3]);
                assert!(
                    resolvable(&network.stations, SOURCE, pos) >= min_res - 1e-3,
                    "{what}"
                );
                let layout = noise.layout();
                let (start, end) = (date_row(&layout, &p["start"]), date_row(&layout, &p["end"]));
                assert!(
                    in_period(&layout, placement, start),
                    "{what}: starts {}",
                    p["start"]
                );
                let lasting = p["shape"] == "lasting";
                let shape = if lasting {
                    Shape::Lasting
                } else {
                    Shape::Pulse
                };
                if lasting {
                    assert!((-1.1..=-0.8).contains(&num("peak_dv_1e6m3")), "{what}");
                    assert!((60..=120).contains(&(end - start)), "{what}");
                    assert!(
                        in_period(&layout, placement, end),
                        "{what}: reaches its volume in its period"
                    );
                }
                // The field of the stated source at the stated volume, on days before, during,
                // at the peak and after.
                let days = (end - start) as f64;
                let mid = if lasting {
                    end
                } else {
                    start + (end - start) / 2
                };
                let mut u = vec![0.0; 36];
                for t in [
                    start.saturating_sub(1),
                    start + 20,
                    mid,
                    end + 1,
                    layout.n_days() - 1,
                ] {
                    let dv = num("peak_dv_1e6m3") * course(shape, t as f64 - start as f64, days);
                    mogi::field(&network.stations, &[pos[0], pos[1], pos[2], dv], &mut u).unwrap();
                    let scale = 1.0 + u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    for c in 0..36 {
                        // Position stated to 1 m, ΔV to 1e-4: 0.2 % of the largest displacement.
                        assert!(
                            (diff[t][c] - u[c]).abs() < 2e-3 * scale,
                            "{what} day {t} channel {c}: {} vs {}",
                            diff[t][c],
                            u[c]
                        );
                    }
                }
                if lasting {
                    let top = u.chunks(12).fold(vec![0.0; 12], |acc, k| {
                        acc.iter().zip(k).map(|(a, v)| a + v * v).collect()
                    });
                    let top = top.iter().fold(0.0f64, |m, v| m.max(v.sqrt()));
                    assert!(
                        top >= MIN_VISIBLE_MM - 0.05,
                        "{what}: largest displacement {top} mm"
                    );
                }
            }
        }
    }
}

/// Least-squares coefficients of `v` on the seasonal basis over the record.
fn seasonal_fit(layout: &Layout, v: &[f64]) -> [f64; 4] {
    let mut a = [[0.0; 5]; 4];
    for (t, y) in v.iter().enumerate() {
        let w = std::f64::consts::TAU * layout.day(t) as f64 / 365.25;
        let b = [w.sin(), w.cos(), (2.0 * w).sin(), (2.0 * w).cos()];
        for i in 0..4 {
            for j in 0..4 {
                a[i][j] += b[i] * b[j];
            }
            a[i][4] += b[i] * y;
        }
    }
    for i in 0..4 {
        for r in (i + 1)..4 {
            let f = a[r][i] / a[i][i];
            for j in i..5 {
                a[r][j] -= f * a[i][j];
            }
        }
    }
    let mut x = [0.0; 4];
    for i in (0..4).rev() {
        x[i] = (a[i][4] - ((i + 1)..4).map(|j| a[i][j] * x[j]).sum::<f64>()) / a[i][i];
    }
    x
}

#[test]
fn latent_and_seasonal_effects_have_their_stated_size() {
    for noise in NoiseModel::ALL {
        let layout = noise.layout();
        let bg = noise::red_common(4, &layout);
        let col = |d: &[Vec<f64>], c: usize| -> Vec<f64> { d.iter().map(|r| r[c]).collect() };
        // Common mode: the same at every station; its RMS over the whole record (with the noise's
        // own common mode, where it has one).
        let (d, t) = added(Spec::new(Scenario::CommonMode, 4).noise(noise));
        let p = &injected(&t)[0].params;
        for k in 0..3 {
            let mut v = col(&d, k * 12);
            assert!(d.iter().all(|r| (r[k * 12 + 7] - r[k * 12]).abs() < MM_TOL));
            if noise == NoiseModel::Red {
                v.iter_mut().zip(&bg.0[k]).for_each(|(x, g)| *x += g);
            }
            let rms = draw::rms_about_mean(&v);
            assert!(
                (rms - p["rms_mm"][k].as_f64().unwrap()).abs() < 1e-3,
                "{noise:?} {k}"
            );
        }
        // Elevation: the vertical offsets are linear in elevation, with the stated RMS slope.
        let (d, t) = added(Spec::new(Scenario::Elevation, 4).noise(noise));
        let p = &injected(&t)[0].params;
        let st = Network::akutan().stations;
        let z_ref = p["z_ref_km"].as_f64().unwrap();
        let slope: Vec<f64> = d.iter().map(|r| r[24] / (st[0].z_km - z_ref)).collect();
        for (r, k) in d.iter().zip(&slope) {
            for i in 0..12 {
                assert!((r[24 + i] - k * (st[i].z_km - z_ref)).abs() < MM_TOL);
            }
        }
        let rms = draw::rms_about_mean(&slope);
        assert!(
            (rms - p["mm_per_km"].as_f64().unwrap()).abs() < 1e-2,
            "{noise:?}"
        );
        // Seasonal: the stated amplitudes are those of the terms in the data (with the noise's
        // annual common term, where it has one).
        let (d, t) = added(Spec::new(Scenario::Seasonal, 4).noise(noise));
        let p = &injected(&t)[0].params;
        for c in [0, 13, 26, 35] {
            let mut v = col(&d, c);
            if noise == NoiseModel::Red {
                let k = c / 12;
                for (t, x) in v.iter_mut().enumerate() {
                    let w = std::f64::consts::TAU * layout.day(t) as f64 / 365.25;
                    *x += bg.1[k][0] * w.sin() + bg.1[k][1] * w.cos();
                }
            }
            let f = seasonal_fit(&layout, &v);
            let name = AKUTAN[c % 12].0;
            for (j, key) in [(0, "annual_mm"), (2, "semiannual_mm")] {
                let want = p[key][name][c / 12].as_f64().unwrap();
                assert!(
                    (f[j].hypot(f[j + 1]) - want).abs() < 1e-3,
                    "{noise:?} {c} {key}"
                );
            }
        }
        // Drift: linear at the stated stations with the stated rates, nothing elsewhere.
        let (d, t) = added(Spec::new(Scenario::Drift, 4).noise(noise));
        let p = &injected(&t)[0].params;
        let rates = p["rate_mm_per_yr"].as_object().unwrap();
        let n = d.len();
        for i in 0..12 {
            for k in 0..3 {
                let per_yr = (d[n - 1][k * 12 + i] - d[0][k * 12 + i]) / ((n - 1) as f64 / 365.25);
                let want = rates
                    .get(AKUTAN[i].0)
                    .map_or(0.0, |r| r[k].as_f64().unwrap());
                assert!(
                    (per_yr - want).abs() < 1e-3,
                    "{noise:?} station {i}: {per_yr} vs {want}"
                );
            }
        }
    }
}

#[test]
fn the_red_truth_lists_what_its_noise_holds() {
    let s = Spec::new(Scenario::Clean, 1)
        .noise(NoiseModel::Red)
        .generate();
    let fams: Vec<String> = background(&s.truth).into_iter().map(|e| e.family).collect();
    assert_eq!(fams, ["common_mode", "seasonal"]);
    assert_eq!(s.truth["noise"], "red");
    assert_eq!(s.truth["placement"], "-");
    assert!(s.truth["effect"].is_null() && injected(&s.truth).is_empty());
    let p = generate(Scenario::Step, 1);
    assert!(background(&p.truth).is_empty());
    assert_eq!(
        injected(&p.truth),
        vec![serde_json::from_value::<Injected>(p.truth["effect"].clone()).unwrap()]
    );
}

/// A network of `n` stations on a ring of `r` km around (`cx`, `cy`), one at its centre.
fn ring(n: usize, r: f64, cx: f64, cy: f64) -> Network {
    let mut net = Network {
        names: vec!["C000".into()],
        stations: vec![magic_core::mogi::Station {
            x_km: cx,
            y_km: cy,
            z_km: 0.4,
        }],
    };
    for i in 1..n {
        let th = std::f64::consts::TAU * i as f64 / (n - 1) as f64;
        net.names.push(format!("R{i:03}"));
        net.stations.push(magic_core::mogi::Station {
            x_km: cx + r * th.cos(),
            y_km: cy + r * th.sin(),
            z_km: 0.2 + 0.05 * i as f64,
        });
    }
    net
}

#[test]
fn another_network_carries_its_own_source_and_bounds() {
    let site = Site::on(ring(9, 8.0, 40.0, -25.0)).unwrap();
    assert!((site.source[0] - 40.0).abs() < 1e-9 && (site.source[1] + 25.0).abs() < 1e-9);
    for sc in [
        Scenario::Clean,
        Scenario::SecondSource,
        Scenario::SecondSourceNear,
        Scenario::LastingDeflationFar,
        Scenario::StepElevation,
    ] {
        let s = Spec::new(sc, 3).generate_on(&site).unwrap();
        assert_eq!(s.problem.network, site.network);
        assert_eq!(s.problem.source_bounds, site.bounds);
        assert_eq!(s.problem.data.columns.len(), 3 * 9);
        assert_eq!(s.truth["source"]["x_km"], 40.0);
        for e in injected(&s.truth)
            .iter()
            .filter(|e| e.family == "second_source")
        {
            let at = |k: &str| e.params[k].as_f64().unwrap();
            let r = (at("x_km") - 40.0).hypot(at("y_km") + 25.0);
            let (lo, hi) = match sc {
                Scenario::SecondSourceNear => (2.0, 4.0),
                Scenario::LastingDeflationFar => (6.0, 12.0),
                _ => (5.0, f64::INFINITY),
            };
            assert!(
                r >= lo && r <= hi,
                "{}: {r} km from the main source",
                sc.name()
            );
        }
    }
    // Akutan as a site is the built-in generator.
    let spec = Spec::new(Scenario::SecondSource, 2);
    assert_eq!(
        fingerprint(&spec.generate_on(&Site::akutan()).unwrap()),
        fingerprint(&spec.generate())
    );
}

#[test]
fn a_network_with_no_room_for_a_scenario_is_an_error() {
    let e = Site::on(ring(4, 5.0, 0.0, 0.0)).unwrap_err().to_string();
    assert!(e.contains("at least 5 stations (found 4)"), "{e}");
    // Stations within 1 km: no far source lies within their box ± 2 km.
    let tiny = Site::on(ring(6, 0.5, 0.0, 0.0)).unwrap();
    let e = Spec::new(Scenario::LastingDeflationFar, 1)
        .generate_on(&tiny)
        .err()
        .expect("no room for a far source")
        .to_string();
    assert!(
        e.contains("no position for a far second source (lasting)"),
        "{e}"
    );
    assert!(Spec::new(Scenario::Step, 1).generate_on(&tiny).is_ok());
}

#[test]
fn a_prepared_folder_lends_the_site_its_bounds() {
    let dir = std::env::temp_dir().join(format!("magic-site-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let s = Spec::new(Scenario::Clean, 1)
        .generate_on(&Site::on(ring(7, 6.0, 10.0, 5.0)).unwrap())
        .unwrap();
    crate::gnss::data::write_dir(&s.problem, &dir).unwrap();
    let stations = dir.join("stations.json");
    let site = Site::read(&stations).unwrap();
    for (a, b) in site.bounds.0.iter().zip(s.problem.source_bounds.0) {
        assert!(
            (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12,
            "{a:?} {b:?}"
        );
    }
    let wide = crate::gnss::SourceBounds::from_network(&site.network, 2.0, [1.0, 15.0]).unwrap();
    wide.write_dir(&dir).unwrap();
    assert_eq!(Site::read(&stations).unwrap().bounds.0[2], [1.0, 15.0]);
    // Bounds that leave the main source out: an error naming the file and the variable.
    let away = crate::gnss::SourceBounds([[20.0, 30.0], [0.0, 10.0], [2.0, 20.0], [-10.0, 10.0]]);
    away.write_dir(&dir).unwrap();
    let e = format!("{:#}", Site::read(&stations).unwrap_err());
    assert!(
        e.contains("bounds.json") && e.contains("x_km 10.000"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
