//! The least-squares fits against known sources, bounds, bad input and singular systems.

use super::*;
use magic_core::effects::{mogi_with_effects, Effect};
use magic_core::mogi::PAPER_BOUNDS;
use magic_core::mogi::{self, Station};
use magic_core::Error;

/// The Akutan network (km), rounded from the data's `stations.json`.
const NET: [Station; 12] = [
    Station {
        x_km: -4.245,
        y_km: 6.222,
        z_km: 0.350,
    },
    Station {
        x_km: -1.768,
        y_km: 2.273,
        z_km: 0.543,
    },
    Station {
        x_km: -5.478,
        y_km: -5.790,
        z_km: 0.298,
    },
    Station {
        x_km: -9.329,
        y_km: -1.453,
        z_km: 0.364,
    },
    Station {
        x_km: 10.695,
        y_km: 0.545,
        z_km: 0.463,
    },
    Station {
        x_km: -7.188,
        y_km: 2.299,
        z_km: 0.521,
    },
    Station {
        x_km: -6.520,
        y_km: -0.666,
        z_km: 0.598,
    },
    Station {
        x_km: -0.323,
        y_km: -4.972,
        z_km: 0.330,
    },
    Station {
        x_km: 2.049,
        y_km: 7.627,
        z_km: 0.405,
    },
    Station {
        x_km: 2.034,
        y_km: 1.202,
        z_km: 0.495,
    },
    Station {
        x_km: 5.726,
        y_km: -2.603,
        z_km: 0.396,
    },
    Station {
        x_km: 14.357,
        y_km: -4.685,
        z_km: 0.457,
    },
];

/// Every fitted unknown within 1e-6 of the truth.
fn assert_recovered(f: &Fit, truth: &[f64]) {
    assert_eq!(f.params().len(), truth.len());
    for (j, (p, t)) in f.params().iter().zip(truth).enumerate() {
        assert!((p - t).abs() < 1e-6, "p{j}: {p} vs {t}");
    }
}

fn scales() -> [f64; 36] {
    core::array::from_fn(|c| 1.0 + 0.25 * (c % 5) as f64)
}

fn synth(effects: &[Effect<'_>], truth: &[f64]) -> [f64; 36] {
    let mut y = [0.0; 36];
    mogi_with_effects(&NET, effects, truth, f64::NAN, &mut y).unwrap();
    y
}

fn bounds_with(extra: &[[f64; 2]]) -> ([[f64; 2]; MAX_UNKNOWNS], usize) {
    let mut b = [[0.0; 2]; MAX_UNKNOWNS];
    b[..4].copy_from_slice(&PAPER_BOUNDS);
    b[4..4 + extra.len()].copy_from_slice(extra);
    (b, 4 + extra.len())
}

#[test]
fn recovers_a_known_source_from_noiseless_data() {
    let truth = [1.3, 0.4, 7.2, 3.1];
    let y = synth(&[], &truth);
    let sc = scales();
    let pb = Problem {
        stations: &NET,
        effects: &[],
        bounds: &PAPER_BOUNDS,
        scale: &sc,
    };
    let f = fit(
        &pb,
        &y,
        f64::NAN,
        &[5.0, 3.0, 12.0, 0.5],
        &Options::default(),
    )
    .unwrap();
    assert!(f.converged);
    assert_recovered(&f, &truth);
    assert!(f.cost < 1e-20, "cost {}", f.cost);
    let g = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
    assert_recovered(&g, &truth);
    assert_eq!(g.n_used, 36);
    assert!((cost(&pb, &y, f64::NAN, g.params()).unwrap() - g.cost).abs() < 1e-15);
}

#[test]
fn deflation_and_missing_channels() {
    let truth = [-2.0, 2.5, 4.0, -1.5];
    let mut y = synth(&[], &truth);
    for c in [0, 7, 13, 20, 35] {
        y[c] = f64::NAN;
    }
    let sc = scales();
    let pb = Problem {
        stations: &NET,
        effects: &[],
        bounds: &PAPER_BOUNDS,
        scale: &sc,
    };
    let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
    assert_eq!(f.n_used, 31);
    assert_recovered(&f, &truth);
}

#[test]
fn recovers_the_translation_with_common_mode() {
    let effects = [Effect::CommonMode];
    let truth = [2.0, 1.0, 6.0, 2.5, 4.0, -3.0, 7.5];
    let y = synth(&effects, &truth);
    let sc = scales();
    let (b, n) = bounds_with(&[[-30.0, 30.0]; 3]);
    let pb = Problem {
        stations: &NET,
        effects: &effects,
        bounds: &b[..n],
        scale: &sc,
    };
    assert_eq!(pb.n_unknowns(), 7);
    let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
    assert!(f.converged);
    assert_eq!(f.params().len(), 7);
    assert_recovered(&f, &truth);
}

#[test]
fn recovers_elevation_and_second_source_terms() {
    let effects = [
        Effect::CommonMode,
        Effect::Elevation { z_ref_km: 0.34 },
        Effect::SecondSource {
            x_km: 9.0,
            y_km: -3.0,
            depth_km: 3.0,
        },
    ];
    let truth = [0.5, 1.5, 8.0, 4.0, -1.0, 2.0, 0.5, 12.0, -0.8];
    // 9 unknowns exceed the solver's size: an error, not a panic.
    let sc = scales();
    let (b, _) = bounds_with(&[[-30.0, 30.0]; 4]);
    let mut b9 = [[0.0; 2]; 9];
    b9[..8].copy_from_slice(&b);
    b9[8] = [-10.0, 10.0];
    let pb = Problem {
        stations: &NET,
        effects: &effects,
        bounds: &b9,
        scale: &sc,
    };
    assert!(matches!(
        fit_grid(
            &pb,
            &[0.0; 36],
            f64::NAN,
            &Grid::default(),
            &Options::default()
        ),
        Err(Error::SizeMismatch { .. })
    ));
    // Elevation and second source without the common mode: 6 unknowns.
    let effects = [effects[1], effects[2]];
    let truth = [truth[0], truth[1], truth[2], truth[3], truth[7], truth[8]];
    let y = synth(&effects, &truth);
    let (b, n) = bounds_with(&[[-200.0, 200.0], [-10.0, 10.0]]);
    let pb = Problem {
        stations: &NET,
        effects: &effects,
        bounds: &b[..n],
        scale: &sc,
    };
    let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
    assert_recovered(&f, &truth);
}

#[test]
fn stops_on_a_bound() {
    // A source shallower than the bounds allow: the depth ends on its minimum, converged.
    let y = synth(&[], &[1.0, 1.0, 1.0, 0.3]);
    let sc = [1.0; 36];
    let pb = Problem {
        stations: &NET,
        effects: &[],
        bounds: &PAPER_BOUNDS,
        scale: &sc,
    };
    let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
    assert_eq!(f.params[2], PAPER_BOUNDS[2][0]);
    assert!(f.converged && f.cost.is_finite());
    for (v, [lo, hi]) in f.params().iter().zip(PAPER_BOUNDS) {
        assert!((lo..=hi).contains(v));
    }
}

#[test]
fn noisy_data_fit_is_no_worse_than_the_truth() {
    let truth = [3.0, -1.0, 9.0, 5.0];
    let mut y = synth(&[], &truth);
    let mut s = 12345u32;
    for v in y.iter_mut() {
        s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        *v += ((s >> 8) as f64 / (1u32 << 24) as f64 - 0.5) * 2.0;
    }
    let sc = scales();
    let pb = Problem {
        stations: &NET,
        effects: &[],
        bounds: &PAPER_BOUNDS,
        scale: &sc,
    };
    let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
    assert!(f.cost <= cost(&pb, &y, f64::NAN, &truth).unwrap());
    assert!(f.converged);
}

#[test]
fn wrong_sizes_and_non_finite_inputs_are_errors() {
    let sc = [1.0; 36];
    let y = synth(&[], &[1.0, 1.0, 6.0, 1.0]);
    let pb = Problem {
        stations: &NET,
        effects: &[],
        bounds: &PAPER_BOUNDS,
        scale: &sc,
    };
    let o = Options::default();
    let start = [0.0, 0.0, 5.0, 0.0];
    // Wrong sizes.
    assert!(matches!(
        fit(&pb, &y[..35], f64::NAN, &start, &o),
        Err(Error::SizeMismatch { .. })
    ));
    assert!(matches!(
        fit(&pb, &y, f64::NAN, &start[..3], &o),
        Err(Error::SizeMismatch { .. })
    ));
    let short = Problem {
        scale: &sc[..30],
        ..pb
    };
    assert!(matches!(
        fit(&short, &y, f64::NAN, &start, &o),
        Err(Error::SizeMismatch { .. })
    ));
    let nob = Problem {
        bounds: &PAPER_BOUNDS[..3],
        ..pb
    };
    assert!(matches!(
        fit(&nob, &y, f64::NAN, &start, &o),
        Err(Error::SizeMismatch { .. })
    ));
    let none = Problem {
        stations: &[],
        scale: &[],
        ..pb
    };
    assert!(fit(&none, &[], f64::NAN, &start, &o).is_err());
    // Non-finite inputs.
    let mut bad = y;
    bad[3] = f64::INFINITY;
    assert!(matches!(
        fit(&pb, &bad, f64::NAN, &start, &o),
        Err(Error::NonFinite { index: 3, .. })
    ));
    assert!(matches!(
        fit(&pb, &y, f64::NAN, &[f64::NAN, 0.0, 5.0, 0.0], &o),
        Err(Error::NonFinite { .. })
    ));
    let mut nsc = sc;
    nsc[5] = f64::NAN;
    assert!(fit(&Problem { scale: &nsc, ..pb }, &y, f64::NAN, &start, &o).is_err());
    nsc[5] = 0.0;
    assert!(fit(&Problem { scale: &nsc, ..pb }, &y, f64::NAN, &start, &o).is_err());
}

#[test]
fn bad_bounds_sparse_data_bad_grids_and_undated_effects_are_errors() {
    let sc = [1.0; 36];
    let y = synth(&[], &[1.0, 1.0, 6.0, 1.0]);
    let pb = Problem {
        stations: &NET,
        effects: &[],
        bounds: &PAPER_BOUNDS,
        scale: &sc,
    };
    let o = Options::default();
    let start = [0.0, 0.0, 5.0, 0.0];
    // Bounds: inverted, non-finite, depth not positive.
    let mut b = PAPER_BOUNDS;
    b[0] = [1.0, -1.0];
    assert!(matches!(
        fit(&Problem { bounds: &b, ..pb }, &y, f64::NAN, &start, &o),
        Err(Error::OutOfRange { .. })
    ));
    b[0] = [f64::NEG_INFINITY, 1.0];
    assert!(fit(&Problem { bounds: &b, ..pb }, &y, f64::NAN, &start, &o).is_err());
    let mut b = PAPER_BOUNDS;
    b[2] = [0.0, 20.0];
    assert!(fit(&Problem { bounds: &b, ..pb }, &y, f64::NAN, &start, &o).is_err());
    // Too few observed channels.
    let mut sparse = [f64::NAN; 36];
    sparse[..3].copy_from_slice(&y[..3]);
    assert!(matches!(
        fit(&pb, &sparse, f64::NAN, &start, &o),
        Err(Error::TooFewObservations {
            observed: 3,
            needed: 4
        })
    ));
    assert!(fit_grid(&pb, &[f64::NAN; 36], f64::NAN, &Grid::default(), &o).is_err());
    // Grid without points or with too many kept.
    assert!(fit_grid(
        &pb,
        &y,
        f64::NAN,
        &Grid {
            nx: 0,
            ..Grid::default()
        },
        &o
    )
    .is_err());
    assert!(fit_grid(
        &pb,
        &y,
        f64::NAN,
        &Grid {
            keep: 9,
            ..Grid::default()
        },
        &o
    )
    .is_err());
    // Time-dependent effect without a date.
    let rate = [0u8; 4 * 36];
    let eff = [Effect::Drift {
        t0_day: 0.0,
        rate: magic_core::quant::LeF32(&rate),
    }];
    assert!(fit(
        &Problem {
            effects: &eff,
            ..pb
        },
        &y,
        f64::NAN,
        &start,
        &o
    )
    .is_err());
    assert!(fit(
        &Problem {
            effects: &eff,
            ..pb
        },
        &y,
        100.0,
        &start,
        &o
    )
    .is_ok());
}

#[test]
fn singular_systems_are_damped_not_fatal() {
    // Every station at one point: x, y and depth are not separable; no panic, finite result.
    let st = [Station {
        x_km: 1.0,
        y_km: 1.0,
        z_km: 0.0,
    }; 4];
    let mut y = [0.0; 12];
    mogi::field(&st, &[0.0, 0.0, 5.0, 1.0], &mut y).unwrap();
    let sc = [1.0; 12];
    let pb = Problem {
        stations: &st,
        effects: &[],
        bounds: &PAPER_BOUNDS,
        scale: &sc,
    };
    let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
    assert!(f.cost.is_finite() && f.cost < 1e-12);
    // Zero volume change: the Jacobian columns of x, y, depth vanish.
    let f = fit(
        &pb,
        &[0.0; 12],
        f64::NAN,
        &[0.0, 0.0, 5.0, 0.0],
        &Options::default(),
    )
    .unwrap();
    assert!(f.converged && f.cost == 0.0);
    // A flat (zero-width) bound holds its unknown.
    let mut b = PAPER_BOUNDS;
    b[2] = [5.0, 5.0];
    let f = fit(
        &Problem { bounds: &b, ..pb },
        &y,
        f64::NAN,
        &[3.0, 3.0, 9.0, 0.0],
        &Options::default(),
    )
    .unwrap();
    assert_eq!(f.params[2], 5.0);
}
