//! The recovery rules on hand-made candidates.

use super::*;
use crate::model::OwnedEffect;

/// A candidate of `family` with `params`, significant or not, declarable or not.
fn cand(family: &str, significant: bool, params: serde_json::Value) -> Candidate {
    let noise = vec![0.010, 0.012, 0.008, 0.011, 0.009, 0.010, 0.013, 0.007];
    let score = if significant { 0.2 } else { 0.0 };
    let c = Candidate::from_scores(
        family,
        score,
        noise,
        0.95,
        params,
        Some(OwnedEffect::CommonMode),
    );
    assert_eq!(c.significant, significant);
    c
}

fn step_truth(epoch: &str) -> serde_json::Value {
    json!({"family": "step", "params": {"station": "AV13", "epoch": epoch, "offset_mm": [1, 2, 3]}})
}

#[test]
fn one_effect_found_and_ranked_first() {
    let truth = json!({"scenario": "step", "seed": 3, "noise": "paper", "placement": "valid",
        "effects": [step_truth("2014-03-01")], "background": []});
    let step = |epoch: &str| {
        cand(
            "step",
            true,
            json!({"station": "AV13", "epoch": epoch, "offset_mm": [1, 2, 3]}),
        )
    };
    let r = recovery(
        &truth,
        &[step("2014-03-09"), cand("drift", false, json!({}))],
    );
    assert!(r.ok() && r.all_found(), "{r:?}");
    assert_eq!(
        (r.ranked_first(), r.placement.as_str()),
        (Some(true), "valid")
    );
    // 11 days off: not recovered.
    let r = recovery(&truth, &[step("2014-03-12")]);
    assert!(!r.ok() && r.effects[0].significant && !r.effects[0].params_ok);
    // Found but ranked second behind a false addition.
    let r = recovery(
        &truth,
        &[cand("drift", true, json!({})), step("2014-03-01")],
    );
    assert!(r.all_found() && !r.ok());
    assert_eq!(r.false_additions, ["drift"]);
    assert_eq!(r.effects[0].rank, Some(2));
}

#[test]
fn two_effects_are_both_needed_in_any_order() {
    let truth = json!({"scenario": "step+elevation", "effects": [step_truth("2010-01-01"),
        {"family": "elevation", "params": {"mm_per_km": 30.0}}]});
    let step = cand(
        "step",
        true,
        json!({"station": "AV13", "epoch": "2010-01-05", "offset_mm": [0, 0, 0]}),
    );
    let elev = |v: f64, sig: bool| cand("elevation", sig, json!({"mm_per_km": v}));
    let r = recovery(&truth, &[elev(35.0, true), step.clone()]);
    assert!(r.ok() && r.ranked_first().is_none(), "{r:?}");
    let r = recovery(&truth, &[step.clone(), elev(35.0, true)]);
    assert!(r.ok());
    // Slope 40 % off, or not significant: one of two is not enough.
    assert!(!recovery(&truth, &[step.clone(), elev(42.0, true)]).ok());
    assert!(!recovery(&truth, &[step, elev(30.0, false)]).ok());
}

#[test]
fn clean_data_count_false_additions_but_not_what_the_noise_holds() {
    let cm = cand("common_mode", true, json!({"rms_mm": [1, 1, 2]}));
    let truth = json!({"scenario": "clean", "noise": "red", "placement": "-", "effects": [],
        "background": [{"family": "common_mode", "params": {"rms_mm": [1, 1, 2]}}]});
    let r = recovery(&truth, &[cm.clone(), cand("step", false, json!({}))]);
    assert!(r.ok(), "{r:?}");
    assert_eq!(r.background_found, ["common_mode"]);
    assert_eq!(r.top, "step", "ranks skip what the noise holds");
    let mut undeclarable = cand("seasonal", true, json!({}));
    undeclarable.effect = None;
    assert!(recovery(&truth, &[cm.clone(), undeclarable]).ok());
    let r = recovery(&truth, &[cm, cand("elevation", true, json!({}))]);
    assert!(!r.ok());
    assert_eq!(r.false_additions, ["elevation"]);
    // An older truth file: a null `effect`, no background.
    let r = recovery(
        &json!({"scenario": "clean", "seed": 1, "effect": null}),
        &[cand("common_mode", true, json!({}))],
    );
    assert_eq!(r.false_additions, ["common_mode"]);
    assert_eq!((r.noise.as_str(), r.placement.as_str()), ("paper", "train"));
}

#[test]
fn parameter_rules() {
    let src = json!({"x_km": 5.0, "y_km": 1.0, "depth_km": 4.0, "start": "2010-01-01", "end": "2010-06-01"});
    let near = json!({"x_km": 6.2, "y_km": 2.5, "depth_km": 6.0});
    let far = json!({"x_km": 6.5, "y_km": 2.5, "depth_km": 4.0});
    assert!(compare("second_source", &src, &near).0);
    assert!(!compare("second_source", &src, &far).0);
    let cm = json!({"rms_mm": [2.0, 2.0, 4.0]});
    assert!(compare("common_mode", &cm, &json!({"rms_mm": [2.5, 1.5, 5.0]})).0);
    assert!(!compare("common_mode", &cm, &json!({"rms_mm": [2.0, 2.0, 5.3]})).0);
    let d = json!({"rate_mm_per_yr": {"AV06": [1, 1, 1], "AKGG": [1, 1, 1]}});
    assert!(
        compare(
            "drift",
            &d,
            &json!({"rate_mm_per_yr": {"AKGG": [0, 0, 0], "AV06": [0, 0, 0]}})
        )
        .0
    );
    assert!(!compare("drift", &d, &json!({"rate_mm_per_yr": {"AKGG": [0, 0, 0]}})).0);
    let s = json!({"annual_mm": {"A": [1.0, 2.0, 4.0], "B": [1.0, 1.0, 1.0]}});
    assert!(
        compare(
            "seasonal",
            &s,
            &json!({"annual_mm": {"A": [1.1, 2.5, 4.0], "B": [1.0, 2.0, 0.9]}})
        )
        .0
    );
    assert!(
        !compare(
            "seasonal",
            &s,
            &json!({"annual_mm": {"A": [2.0, 3.0, 6.0], "B": [1.5, 2.0, 0.9]}})
        )
        .0
    );
    assert!(!compare("nothing", &s, &s).0);
}

#[test]
fn the_table_counts_per_scenario_placement_and_noise() {
    let truth = |seed: u64, noise: &str| {
        json!({"scenario": "step", "seed": seed, "noise": noise, "placement": "test",
            "effects": [step_truth("2007-01-01")]})
    };
    let hit = cand(
        "step",
        true,
        json!({"station": "AV13", "epoch": "2007-01-02", "offset_mm": [0, 0, 0]}),
    );
    let rows = vec![
        recovery(&truth(1, "paper"), std::slice::from_ref(&hit)),
        recovery(
            &truth(2, "paper"),
            &[cand("drift", true, json!({})), hit.clone()],
        ),
        recovery(&truth(1, "red"), &[hit]),
    ];
    let t = recovery_table(&rows);
    let lines: Vec<&str> = t.lines().collect();
    assert_eq!(lines.len(), 4, "{t}");
    assert_eq!(
        lines[2],
        "| step | test | paper | 2 | 2/2 | 1/2 | 2/2 | 1/2 (drift 1/2) | - | 1/2 |"
    );
    assert_eq!(
        lines[3],
        "| step | test | red | 1 | 1/1 | 1/1 | 1/1 | 0/1 | - | 1/1 |"
    );
}

#[test]
fn a_source_found_as_the_other_time_course_is_not_a_false_addition() {
    let src = json!({"x_km": 4.0, "y_km": -2.0, "depth_km": 5.0});
    let truth = json!({"scenario": "second_source", "noise": "paper", "placement": "train",
        "effects": [{"family": "second_source", "params": src}], "background": []});
    let r = recovery(
        &truth,
        &[
            cand("second_source", true, src.clone()),
            cand("lasting_source", true, src.clone()),
            cand("drift", true, json!({})),
        ],
    );
    assert_eq!(r.false_additions, ["drift"]);
    assert!(same_effect("lasting_source", "second_source") && !same_effect("step", "drift"));
}

#[test]
fn a_source_found_as_the_other_time_course_is_found() {
    let src = json!({"x_km": 4.0, "y_km": -2.0, "depth_km": 5.0});
    let truth = json!({"scenario": "second_source", "noise": "paper", "placement": "test",
        "effects": [{"family": "second_source", "params": src}], "background": []});
    let off = json!({"x_km": 9.0, "y_km": -2.0, "depth_km": 5.0});
    // The loop adds the significant lasting source at the right place: found, first.
    let r = recovery(
        &truth,
        &[
            cand("lasting_source", true, src.clone()),
            cand("second_source", true, off.clone()),
        ],
    );
    assert!(r.ok(), "{r:?}");
    assert!(
        r.effects[0].detail.starts_with("as lasting_source"),
        "{r:?}"
    );
    // A significant one at the wrong place ranked above the right one: found, not first.
    let r = recovery(
        &truth,
        &[
            cand("lasting_source", true, off.clone()),
            cand("second_source", true, src.clone()),
        ],
    );
    assert!(
        r.all_found() && r.effects[0].rank == Some(2) && !r.ok(),
        "{r:?}"
    );
    // Only at the wrong place: judged there, not found.
    let r = recovery(
        &truth,
        &[
            cand("lasting_source", true, off),
            cand("second_source", false, src),
        ],
    );
    assert!(!r.all_found() && !r.effects[0].params_ok, "{r:?}");
    assert!(
        r.effects[0].detail.starts_with("as lasting_source"),
        "{r:?}"
    );
}

#[test]
fn a_change_found_in_the_last_year_is_the_lasting_family_ranked_first() {
    let src = json!({"x_km": 4.0, "y_km": -2.0, "depth_km": 3.5});
    let truth = json!({"scenario": "lasting_deflation_far", "noise": "paper",
        "placement": "valid", "effects": [{"family": "lasting_source", "params": src}],
        "background": []});
    // Found by both searches, the last year's ranked first: found, first, nothing false.
    let r = recovery(
        &truth,
        &[
            cand("recent_source", true, src.clone()),
            cand("lasting_source", true, src.clone()),
            cand("second_source", false, src.clone()),
        ],
    );
    assert!(r.ok() && r.effects[0].rank == Some(1), "{r:?}");
    assert!(r.false_additions.is_empty(), "{r:?}");
    assert!(same_family("recent_source", "lasting_source"));
    assert!(!same_family("second_source", "lasting_source"));
    // A pulse ranked above it is still not the family ranked first.
    let r = recovery(
        &truth,
        &[
            cand("second_source", true, src.clone()),
            cand("recent_source", true, src),
        ],
    );
    assert!(r.all_found() && !r.ok(), "{r:?}");
}

#[test]
fn one_candidate_recovers_one_of_two_injected_sources() {
    let at = |x: f64, y: f64| json!({"x_km": x, "y_km": y, "depth_km": 4.0});
    let truth = json!({"scenario": "second_source+lasting_source", "noise": "red",
        "placement": "valid", "effects": [{"family": "second_source", "params": at(8.4, -0.4)},
        {"family": "lasting_source", "params": at(9.0, -2.3)}], "background": []});
    // One lasting source between the two, within 2 km of each: it recovers the deflation
    // (its own family first); the pulse's candidate is elsewhere.
    let between = cand("lasting_source", true, at(8.9, -1.3));
    let r = recovery(
        &truth,
        &[between.clone(), cand("second_source", true, at(2.0, 5.0))],
    );
    assert!(r.effects[1].found() && !r.effects[0].found(), "{r:?}");
    assert!(
        r.effects[0]
            .detail
            .ends_with("(recovers another injected effect)"),
        "{r:?}"
    );
    // With the pulse located too, both are found.
    let r = recovery(
        &truth,
        &[between, cand("second_source", true, at(8.0, 0.2))],
    );
    assert!(r.all_found(), "{r:?}");
}
