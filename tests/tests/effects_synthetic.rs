//! The residual analysis finds what F lacks: for every effect family, synthetic data with that
//! effect hidden in it (`magic synth --scenario …`, events in the training period, the original
//! noise model), a B model trained briefly, and the analysis must rank the hidden family first,
//! call it significant and recover its key parameters (a step's station and epoch within 10 days, a
//! second source or a lasting deflation within 2 km, the elevation slope within 30 %, the common
//! mode's RMS and the seasonal amplitudes within 30 %, the drifting stations); on clean data no
//! declarable family may be significant. Two seeds per family; `magic synth-check --seeds 10` runs
//! the full table (with placements, two effects at once and a second noise model).

use magic_train::gnss::recovery::{brief_recipe, check_one};
use magic_train::gnss::synth::{self, Scenario, Site, Spec};
use magic_train::{AnalysisOptions, OwnedEffect};

/// The step offset in the analysis report (JSON) against the effect's f32 offset (mm): the report
/// rounds to 3 decimals (±5e-4 mm), the effect holds f32; measured 2.5e-4.
const REPORTED_OFFSET_MAX_ERROR_MM: f64 = 5.1e-4;
/// F with the step after its epoch minus before against the declared offset (mm): measured 0; the
/// rounding of adding it to displacements of ~100 mm (an ulp is 1.4e-14 mm) allowed.
const APPLIED_OFFSET_MAX_ERROR_MM: f64 = 1e-12;

fn check(scenario: Scenario) {
    check_with(scenario, &AnalysisOptions::default());
}

fn check_with(scenario: Scenario, opts: &AnalysisOptions) {
    let cfg = brief_recipe();
    for seed in [1, 2] {
        let spec = Spec::new(scenario, seed);
        let check = check_one(&spec, &Site::akutan(), &cfg, opts).unwrap();
        let (r, a) = (check.recovery, check.analysis);
        assert!(
            r.ok(),
            "{} seed {seed}: {} ({:?})\n{}",
            scenario.name(),
            r.detail(),
            r,
            a.table()
        );
        // The truth lists what was injected, in the analysis's families and parameter names.
        let injected = synth::truth::injected(&check.truth);
        assert_eq!(injected.len(), scenario.injections().len());
        for (e, f) in injected.iter().zip(&r.effects) {
            assert_eq!(e.family, f.family);
            let fitted = &a
                .effects
                .iter()
                .find(|c| c.family == e.family)
                .unwrap()
                .params;
            for key in e.params.as_object().unwrap().keys() {
                if key != "shape" {
                    assert!(
                        fitted.get(key).is_some(),
                        "{}: `{key}` not reported",
                        e.family
                    );
                }
            }
        }
        // (Its cost is reported, not asserted: `magic synth-check` prints it.)
        eprintln!(
            "{} seed {seed}: analysis {:.1} s",
            scenario.name(),
            a.seconds
        );
        if scenario != Scenario::Clean {
            let top = &a.effects[0];
            assert!(
                top.effect.is_some(),
                "the top candidate carries the effect that adds it to F"
            );
            assert!(top.variance_explained > top.chance_level);
        }
    }
}

#[test]
fn clean_data_has_no_significant_effect() {
    check(Scenario::Clean);
}

#[test]
fn common_mode_is_found() {
    check(Scenario::CommonMode);
}

#[test]
fn seasonal_terms_are_found() {
    check(Scenario::Seasonal);
}

#[test]
fn elevation_term_is_found() {
    check(Scenario::Elevation);
}

#[test]
fn step_is_found_with_station_and_epoch() {
    check(Scenario::Step);
}

#[test]
fn second_source_is_found_and_located() {
    check(Scenario::SecondSource);
}

#[test]
fn drift_is_found_at_its_stations() {
    check(Scenario::Drift);
}

/// A deflation 2–4 km from the main source that builds over months and then stays: found by the
/// default statistic, the matched filter, and located within 2 km (the offsets' scan, the
/// earlier default, found too few of these at the record's ends for a two-seed test).
#[test]
fn a_lasting_deflation_is_found_and_located() {
    check(Scenario::LastingDeflationNear);
}

/// A pulse 2–4 km from the main source is mostly a move of it: located and scored with the main
/// source held in place (the default analysis does so for `second_source`), it is found and
/// located.
#[test]
fn a_near_source_is_found_where_the_main_source_is_held() {
    check(Scenario::SecondSourceNear);
}

#[test]
fn fitted_effect_reproduces_the_fit() {
    // A step found by the analysis, added to F, reproduces the offset it measured: F with the
    // effect evaluated after the epoch minus before equals the offset in mm.
    let cfg = brief_recipe();
    let a = check_one(
        &Spec::new(Scenario::Step, 1),
        &Site::akutan(),
        &cfg,
        &AnalysisOptions::default(),
    )
    .unwrap()
    .analysis;
    let step = a.effects.iter().find(|c| c.family == "step").unwrap();
    let Some(OwnedEffect::Step {
        station,
        epoch_day,
        offset_mm,
    }) = step.effect.clone()
    else {
        panic!("step candidate without a Step effect")
    };
    let params = &step.params;
    let network = synth::generate(Scenario::Step, 1).problem.network;
    assert_eq!(
        params["station"].as_str().unwrap(),
        network.names[station as usize]
    );
    let e = magic_core::time::parse_date(params["epoch"].as_str().unwrap()).unwrap() as f32;
    assert_eq!(e, epoch_day);
    let mut reported = 0f64;
    for (k, &off) in offset_mm.iter().enumerate() {
        let d = (params["offset_mm"][k].as_f64().unwrap() - off as f64).abs();
        reported = reported.max(d);
        assert!(d <= REPORTED_OFFSET_MAX_ERROR_MM, "component {k}: {d:e}");
    }
    let core = OwnedEffect::Step {
        station,
        epoch_day,
        offset_mm,
    }
    .borrow(&[]);
    let st = &network.stations;
    let (mut before, mut after) = (vec![0.0f64; 36], vec![0.0f64; 36]);
    core.apply(st, &[], epoch_day as f64 - 1.0, &mut before)
        .unwrap();
    core.apply(st, &[], epoch_day as f64, &mut after).unwrap();
    let mut applied = 0f64;
    for (k, &off) in offset_mm.iter().enumerate() {
        let c = k * 12 + station as usize;
        let d = (after[c] - before[c] - off as f64).abs();
        applied = applied.max(d);
        assert!(d <= APPLIED_OFFSET_MAX_ERROR_MM, "component {k}: {d:e}");
    }
    eprintln!(
        "step offset: report vs effect {reported:.2e} mm, applied vs declared {applied:.2e} mm"
    );
}

/// `--series` writes the view a point source is searched on: one row per analysed day (its date),
/// each channel in mm (the standardised residuals times the channel's scale), and the lasting
/// search grid's points with their patterns; the CSV round trip keeps every digit of an f64.
#[test]
fn the_residual_series_is_the_analysed_view_in_mm() {
    let spec = Spec::new(Scenario::Clean, 1);
    let check = check_one(
        &spec,
        &Site::akutan(),
        &brief_recipe(),
        &AnalysisOptions::default(),
    )
    .unwrap();
    let dir = std::env::temp_dir().join(format!("magic-series-{}", std::process::id()));
    magic_train::gnss::residuals::series::write(&check.residuals, &dir).unwrap();
    let view = check.residuals.locating();
    let (nc, scale) = (view.nc(), &view.ctx.scale);
    let mut rows = csv::Reader::from_path(dir.join("residuals.csv")).unwrap();
    let head = rows.headers().unwrap().clone();
    assert_eq!(head.len(), nc + 1);
    assert_eq!(&head[0], "date");
    assert_eq!(&head[1], &format!("ux_{}", view.ctx.network.names[0]));
    let mut n = 0;
    for (t, row) in rows.records().enumerate() {
        let row = row.unwrap();
        assert_eq!(
            &row[0],
            magic_train::gnss::families::iso_date(view.fit.days[t])
        );
        for c in 0..nc {
            let v: f64 = row[c + 1].parse().unwrap();
            assert_eq!(v, view.fit.r[t * nc + c] * scale[c], "day {t}, channel {c}");
        }
        n += 1;
    }
    assert_eq!(n, view.fit.len(nc));
    let grid = magic_train::gnss::families::lasting_source::lasting_grid(view);
    let mut rows = csv::Reader::from_path(dir.join("grid.csv")).unwrap();
    assert_eq!(rows.headers().unwrap().len(), nc + 3);
    let mut k = 0;
    for (row, (p, g)) in rows.records().zip(grid.points.iter().zip(&grid.patterns)) {
        let row = row.unwrap();
        for (j, v) in p.iter().chain(g.iter()).enumerate() {
            let want = if j < 3 { *v } else { v * scale[j - 3] };
            assert_eq!(
                row[j].parse::<f64>().unwrap(),
                want,
                "grid row {k}, column {j}"
            );
        }
        k += 1;
    }
    assert_eq!(k, grid.points.len());
    std::fs::remove_dir_all(&dir).unwrap();
}
