//! Tests of the residuals' views: the held direction, the projections and the rules that
//! tell a second source from a move of the main one.

use super::*;
use crate::analysis::LastingStatistic;
use crate::gnss::synth::draw;
use rand::rngs::StdRng;
use rand::SeedableRng;

/// What the views share, for a test: the main source at the origin, no span of its own.
fn plain<'a>(network: &'a Network, scale: &'a [f64], days: &'a [f64]) -> Shared<'a> {
    Shared {
        network,
        scale,
        mse: 0.0,
        main: [0.0; 3],
        source_span: Vec::new(),
        sources_span: Vec::new(),
        trading: Vec::new(),
        splits: &[SplitName::Train],
        days,
    }
}

/// A source at a fixed position whose volume changes, a network translation that overlaps its
/// Jacobian's span, and noise: the held direction is the source's field, the translation's
/// part in the span notwithstanding.
#[test]
fn the_held_source_is_the_field_of_a_source_that_stays_put() {
    let (ns, nc) = (6, 18);
    let mut rng = StdRng::seed_from_u64(7);
    let mut normal = move || draw::normal(&mut rng);
    let scale = vec![1.0; nc];
    let up = translation(&scale, ns, 2);
    // The span: a direction close to the vertical translation (a deep source's uplift) and
    // three random ones.
    let near_up: Vec<f64> = up.iter().map(|u| u + 0.3 * normal()).collect();
    let mut cols: Vec<(Vec<f64>, f64)> = vec![(near_up, 1.0)];
    for _ in 0..3 {
        cols.push(((0..nc).map(|_| normal()).collect(), 1.0));
    }
    let source = orthonormal(&cols, 1e-9, 2);
    let weights = [0.3, 1.0, -0.6, 0.4];
    let field: Vec<f64> = (0..nc)
        .map(|c| source.iter().zip(weights).map(|(q, w)| q[c] * w).sum())
        .collect();
    let norm = dot(&field, &field).sqrt();
    let rows: Vec<Vec<f64>> = (0..2000)
        .map(|t| {
            let a = (t as f64 / 150.0).sin() * 3.0;
            let drift = 4.0 * normal();
            (0..nc)
                .map(|c| a * field[c] + drift * up[c] + 0.05 * normal())
                .collect()
        })
        .collect();
    let translations = translation_basis(&scale, ns);
    let w = held_source(&source, &translations, &rows).unwrap();
    let cos = dot(&w, &field).abs() / norm;
    assert!(cos > 0.9999, "cosine with the source's field {cos}");
    // Without the translations as nuisances the common mode, larger than the source here,
    // would be taken for it.
    let naive = held_source(&source, &[], &rows).unwrap();
    assert!(dot(&naive, &field).abs() / norm < 0.9, "naive direction");
    // A span that holds the translation itself cannot tell the two apart: not held.
    let mut with_up = vec![up.clone()];
    with_up.extend(source[1..].iter().cloned());
    let with_up: Vec<(Vec<f64>, f64)> = with_up.into_iter().map(|q| (q, 1.0)).collect();
    let with_up = orthonormal(&with_up, 1e-9, 2);
    assert!(held_source(&with_up, &translations, &rows).is_none());
}

/// The Akutan network with the synthetic main source: the network, each channel's scale (as the
/// generator weighs them), the main source's position and its span (standardised units).
fn akutan_main_source() -> (Network, Vec<f64>, [f64; 3], Vec<Vec<f64>>) {
    use magic_core::mogi::{field_jacobian, N_PARAMS};
    let network = Network::akutan();
    let (ns, nc) = (network.len(), 3 * network.len());
    let main = crate::gnss::synth::SOURCE;
    let scale: Vec<f64> = (0..nc).map(|c| [1.2, 1.2, 3.5][c / ns]).collect();
    let (mut out, mut jac) = (vec![0.0; nc], vec![[0.0; N_PARAMS]; nc]);
    field_jacobian(
        &network.stations,
        &[main[0], main[1], main[2], 1.0],
        &mut out,
        &mut jac,
    )
    .unwrap();
    let columns: Vec<(Vec<f64>, f64)> = (0..N_PARAMS)
        .map(|j| scaled((0..nc).map(|c| jac[c][j] / scale[c]).collect()))
        .collect();
    let span = orthonormal(&columns, 1e-9, 2);
    (network, scale, [main[0], main[1], main[2]], span)
}

/// Residuals `rows` (one per day) on the network with its main source at `main` and its span.
fn beside_main_source(
    network: &Network,
    scale: &[f64],
    main: [f64; 3],
    span: Vec<Vec<f64>>,
    rows: &[Vec<f64>],
) -> GnssResiduals {
    let days: Vec<f64> = (0..rows.len()).map(|t| t as f64).collect();
    let shared = Shared {
        main,
        source_span: span.clone(),
        sources_span: span,
        ..plain(network, scale, &days)
    };
    view(&shared, rows, Vec::new())
}

/// A source right under a station, shallow, is seen by that station alone (one station's
/// three components cannot place a point source): for either source family it counts only
/// where the other stations confirm it, where the same source deeper needs no confirmation.
/// Scored on the others alone, a change that stays at that station by itself gains nothing; the
/// same change along the source's whole field does.
#[test]
fn a_shallow_source_under_one_station_needs_the_others_to_confirm_it() {
    use crate::analysis::Family;
    use crate::gnss::families::held_station::{station_share, MAX_STATION_SHARE};
    use crate::gnss::families::lasting_source::{LastingFit, LastingSource};
    use crate::gnss::families::second_source::{pattern, SecondSource, SourceFit};
    let (network, scale, main, span) = akutan_main_source();
    let nc = scale.len();
    let ns = network.names.len();
    let flat = vec![vec![0.0; nc]; 10];
    let res = beside_main_source(&network, &scale, main, span.clone(), &flat);
    // The station farthest from the main source, where little of a field is a move of it.
    let far = |s: &magic_core::mogi::Station| (s.x_km - main[0]).hypot(s.y_km - main[1]);
    let (i, st) = (network.stations.iter().enumerate())
        .max_by(|a, b| far(a.1).total_cmp(&far(b.1)))
        .unwrap();
    let under = |depth: f64| [st.x_km, st.y_km, depth];
    let (station, share) = station_share(&res, under(1.25));
    assert_eq!(station, i);
    assert!(share > MAX_STATION_SHARE, "{share}");
    let deep = station_share(&res, under(4.0)).1;
    assert!(deep < MAX_STATION_SHARE, "{deep}");
    let lasting = |pos, onset| LastingFit {
        pos,
        onset,
        ..LastingFit::default()
    };
    let second = |pos| SourceFit {
        pos,
        window: 30,
        ..SourceFit::default()
    };
    let held = LastingSource::WHOLE.held_part(&res, &lasting(under(1.25), 5));
    assert_eq!(held.map(|h| h.part), Some(network.names[i].clone()));
    assert!(LastingSource::WHOLE
        .held_part(&res, &lasting(under(4.0), 5))
        .is_none());
    assert!(SecondSource.held_part(&res, &second(under(4.0))).is_none());
    // A change from day 300 of 600 along the shallow source's field, at its station only or
    // at every station, over a little noise.
    let g = pattern(&res, under(1.25));
    let mut rng = StdRng::seed_from_u64(3);
    let mut rows = |only: bool| -> Vec<Vec<f64>> {
        (0..600)
            .map(|t| {
                (0..nc)
                    .map(|c| {
                        let on = (t >= 300 && (!only || c % ns == i)) as u8 as f64;
                        on * g[c] + 0.01 * (rand::Rng::random::<f64>(&mut rng) - 0.5)
                    })
                    .collect()
            })
            .collect()
    };
    let mut without = |only: bool| {
        let res = beside_main_source(&network, &scale, main, span.clone(), &rows(only));
        let h = LastingSource::WHOLE.held_part(&res, &lasting(under(1.25), 300));
        h.expect("one station holds most of the field").score
    };
    let (alone, whole) = (without(true), without(false));
    assert!(whole > 0.01, "{whole}");
    assert!(alone < 1e-3 * whole, "{alone} against {whole}");
}

/// A source's resolvable share (`second_source::resolvable`): none at the main source itself
/// (its field is the volume's direction), little beside it at its depth, most far from it —
/// and, channels weighted as the synthetic generator weighs them, the generator's own measure.
#[test]
fn a_source_beside_the_main_one_is_mostly_a_move_of_it() {
    use crate::gnss::families::second_source::{rejection, resolvable};
    let (network, scale, main, span) = akutan_main_source();
    let nc = scale.len();
    let rows = vec![vec![0.0; nc]; 10];
    let res = beside_main_source(&network, &scale, main, span, &rows);
    let at = |p: [f64; 3]| resolvable(&res, p);
    assert!(at([main[0], main[1], main[2]]) < 1e-6);
    assert!(at([main[0], main[1] + 3.0, main[2]]) < 0.25);
    assert!(at([main[0] + 10.0, main[1] - 4.0, 5.0]) > 0.5);
    // The search prefers a candidate no rule rejects: the move, and the grid's deepest
    // bound, are rejected; the far source is not.
    use crate::analysis::{Rejection, Side};
    let beside = rejection(&res, [main[0], main[1] + 3.0, main[2]]);
    assert!(
        matches!(beside, Some(Rejection::Unresolvable { .. })),
        "{beside:?}"
    );
    let deepest = rejection(&res, [main[0] + 10.0, main[1] - 4.0, 20.0]);
    assert_eq!(deepest.and_then(|r| r.bound()), Some(("depth", Side::High)));
    assert_eq!(rejection(&res, [main[0] + 10.0, main[1] - 4.0, 5.0]), None);
    // A lasting source is held to the same rules, on its own (shallower) grid.
    use crate::analysis::Family;
    use crate::gnss::families::lasting_source::{LastingFit, LastingSource};
    let fit = |pos: [f64; 3]| LastingFit {
        pos,
        ..LastingFit::default()
    };
    let lasting = |pos: [f64; 3]| LastingSource::WHOLE.reject(&res, &fit(pos));
    let beside = lasting([main[0], main[1] + 3.0, main[2]]);
    assert!(
        matches!(beside, Some(Rejection::Unresolvable { .. })),
        "{beside:?}"
    );
    let shallowest = lasting([main[0] + 10.0, main[1] - 4.0, 1.0]);
    assert_eq!(
        shallowest.and_then(|r| r.bound()),
        Some(("depth", Side::Low))
    );
    assert_eq!(lasting([main[0] + 10.0, main[1] - 4.0, 5.0]), None);
    for p in [
        [2.5, 2.0, 3.5],
        [-1.5, 2.0, 3.0],
        [8.0, -3.0, 6.0],
        [0.3, 3.2, 7.0],
    ] {
        let generator =
            crate::gnss::synth::resolvable(&network.stations, crate::gnss::synth::SOURCE, p);
        assert!(
            (at(p) - generator).abs() < 1e-6,
            "{p:?}: {} vs {generator}",
            at(p)
        );
    }
}

/// The lasting source is located only where its field is not mostly a move of the main
/// source: a change that stays, at a point beside the main source that such a move mimics, is
/// located at a resolvable point (refined again within that region, and so not rejected as a
/// move), never at its own — by either statistic.
#[test]
fn the_lasting_source_is_located_where_a_move_cannot_mimic_it() {
    use crate::analysis::{Family, Rejection};
    use crate::gnss::families::lasting_source::LastingSource;
    use crate::gnss::families::second_source::{resolvable, MIN_RESOLVABLE};
    use magic_core::mogi::field;
    let (network, scale, main, span) = akutan_main_source();
    let nc = scale.len();
    // A deflation beside the main source, at its depth, from day 500 of 1 000 on; a little
    // white noise.
    let beside = [main[0], main[1] + 3.0, main[2]];
    let mut u = vec![0.0; nc];
    field(
        &network.stations,
        &[beside[0], beside[1], beside[2], -1.0],
        &mut u,
    )
    .unwrap();
    let mut rng = StdRng::seed_from_u64(3);
    let rows: Vec<Vec<f64>> = (0..1000)
        .map(|t| {
            let on = if t >= 500 { 1.0 } else { 0.0 };
            (0..nc)
                .map(|c| on * u[c] / scale[c] + 0.01 * draw::normal(&mut rng))
                .collect()
        })
        .collect();
    let res = beside_main_source(&network, &scale, main, span, &rows);
    assert!(resolvable(&res, beside) < MIN_RESOLVABLE);
    for statistic in [LastingStatistic::Matched, LastingStatistic::Scan] {
        let family = LastingSource::WHOLE.by(statistic);
        let fit = family.fit(&res).unwrap();
        assert!(
            resolvable(&res, fit.pos) >= MIN_RESOLVABLE,
            "{statistic:?}: located at {:?}",
            fit.pos
        );
        let why = family.reject(&res, &fit);
        assert!(
            !matches!(why, Some(Rejection::Unresolvable { .. })),
            "{statistic:?}: {why:?}"
        );
    }
}

/// The matched filter ([`LastingStatistic::Matched`]) finds a change that stays in slow noise
/// where and when it is: a deflation 6 km from the main source building over 90 days from day
/// 2 000 of 3 000, in white plus AR(1) noise (persistence 0.99, four times the white's
/// variance) on every channel. Located within 2 km (the recovery check's rule; 1.1 km off here,
/// |z| 11.4), its ramp's middle within the change, its |z| more than twice what the same noise
/// gives alone (4.1); the family's fit at the truth too, its onset within the change.
#[test]
fn the_matched_filter_finds_a_change_that_stays_in_slow_noise() {
    use crate::analysis::Family;
    use crate::gnss::families::lasting_source::{fit_at, LastingSource};
    use magic_core::mogi::field;
    let (network, scale, main, span) = akutan_main_source();
    let nc = scale.len();
    let truth = [main[0] + 4.0, main[1] - 4.5, 3.0];
    let mut u = vec![0.0; nc];
    field(
        &network.stations,
        &[truth[0], truth[1], truth[2], -1.0],
        &mut u,
    )
    .unwrap();
    let mut rng = StdRng::seed_from_u64(11);
    let (phi, rho) = (0.99_f64, 4.0_f64);
    let mut ar: Vec<f64> = (0..nc)
        .map(|_| rho.sqrt() * draw::normal(&mut rng))
        .collect();
    let noise: Vec<Vec<f64>> = (0..3000)
        .map(|_| {
            ar.iter_mut()
                .map(|a| {
                    *a = phi * *a + (rho * (1.0 - phi * phi)).sqrt() * draw::normal(&mut rng);
                    *a + draw::normal(&mut rng)
                })
                .collect()
        })
        .collect();
    let with: Vec<Vec<f64>> = noise
        .iter()
        .enumerate()
        .map(|(t, row)| {
            let on = ((t as f64 - 2000.0) / 90.0).clamp(0.0, 1.0);
            row.iter()
                .zip(&u)
                .zip(&scale)
                .map(|((n, v), s)| n + on * v / s)
                .collect()
        })
        .collect();
    let family = LastingSource::WHOLE.by(LastingStatistic::Matched);
    let res = beside_main_source(&network, &scale, main, span.clone(), &with);
    let fit = family.fit(&res).unwrap();
    let off = (fit.pos[0] - truth[0]).hypot(fit.pos[1] - truth[1]);
    let day = res.locating().fit.days[fit.onset];
    assert!(off < 2.0, "found {fit:?}, truth {truth:?}");
    assert!(
        (2000.0..=2090.0).contains(&day),
        "ramp's middle on day {day}"
    );
    let alone = family
        .fit(&beside_main_source(&network, &scale, main, span, &noise))
        .unwrap();
    assert!(
        fit.stat.sqrt() > 2.0 * alone.stat.sqrt() && fit.score > 0.0,
        "|z| {} with the change, {} without",
        fit.stat.sqrt(),
        alone.stat.sqrt()
    );
    let at = fit_at(family, &res, truth, (2000.0, 2090.0)).unwrap();
    let at_day = res.locating().fit.days[at.onset];
    assert!((2000.0..=2090.0).contains(&at_day), "at the truth {at:?}");
    assert!(at.stat > 4.0 * alone.stat, "at the truth {at:?}");
}

/// The free residuals are the held ones projected off the rest of the main source's span
/// (the held direction lies within it); a draw of the free residuals given back the held
/// view's part beyond them ([`GnssResiduals::beside_moves`]) keeps that part as the data
/// hold it and is, projected, the draw again; a draw of the held view projected back
/// ([`GnssResiduals::with_held`]) is seen as the data are.
#[test]
fn the_free_view_is_the_held_view_projected() {
    let network = Network::akutan();
    let (ns, nc) = (network.len(), 3 * network.len());
    let mut rng = StdRng::seed_from_u64(11);
    let mut normal = move || draw::normal(&mut rng);
    let columns: Vec<(Vec<f64>, f64)> = (0..5)
        .map(|_| ((0..nc).map(|_| normal()).collect(), 1.0))
        .collect();
    let rows: Vec<Vec<f64>> = (0..400)
        .map(|t| {
            let a = (t as f64 / 40.0).sin();
            (0..nc)
                .map(|c| a * columns[0].0[c] + 0.3 * a * columns[2].0[c] + normal())
                .collect()
        })
        .collect();
    let scale = vec![1.0; nc];
    let days: Vec<f64> = (0..rows.len()).map(|t| t as f64).collect();
    let shared = plain(&network, &scale, &days);
    let source = orthonormal(&columns[..SOURCE_VARIABLES], 1e-9, 1);
    let held = held_tangent(&source, &columns[SOURCE_VARIABLES..], &scale, ns, &rows)
        .expect("held in place");
    let held = view(&shared, &rows, held);
    let mut free = view(&shared, &rows, orthonormal(&columns, 1e-9, 1));
    let largest = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
    };
    let gap = largest(&free.project_rows(&held.fit.r), &free.fit.r);
    assert!(gap < 1e-12, "free vs held projected: {gap}");
    assert!(std::ptr::eq(free.locating(), &free));
    let noise: Vec<f64> = (0..free.fit.r.len()).map(|_| normal()).collect();
    let drawn = free.with_fit(free.project_rows(&noise));
    let same = free.beside_moves(drawn.clone(), &held.fit.r);
    assert!(same.held.is_none(), "no held view, nothing given back");
    free.held = Some(Arc::new(held.clone()));
    assert!(std::ptr::eq(free.locating(), free.held.as_deref().unwrap()));
    let again = free.with_held(held.clone());
    let gap = largest(&again.fit.r, &free.fit.r);
    assert!(gap < 1e-12, "the held view projected back: {gap}");
    assert_eq!(
        again.held.as_deref().expect("a held view").fit.r,
        held.fit.r
    );
    let out = free.beside_moves(drawn.clone(), &held.fit.r);
    assert_eq!(out.fit.r, drawn.fit.r);
    let out_held = out.held.as_deref().expect("a held view");
    let gap = largest(&free.project_rows(&out_held.fit.r), &drawn.fit.r);
    assert!(gap < 1e-12, "the draw's held view projected: {gap}");
    let minus = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x - y).collect::<Vec<_>>();
    let gap = largest(
        &minus(&out_held.fit.r, &out.fit.r),
        &minus(&held.fit.r, &free.fit.r),
    );
    assert!(gap < 1e-12, "the part beyond the free view: {gap}");
    assert!(free.with_fit(free.fit.r.clone()).held.is_none());
}

/// Per channel, the least-squares coefficients of 1, the annual sine and cosine over `days`.
fn annual(r: &[f64], days: &[f64], nc: usize) -> Vec<Vec<f64>> {
    let w = std::f64::consts::TAU / 365.25;
    let basis = |d: f64, b: &mut [f64]| {
        b[0] = 1.0;
        b[1] = (w * d).sin();
        b[2] = (w * d).cos();
    };
    crate::gnss::families::dated::fit_basis(r, days, nc, 3, &basis)
}

/// An annual term along the main source's field, off the network's translations: the
/// projection takes it off every day, the rows given back hold it whole (a least-squares sine
/// per channel recovers it). Of an annual network translation, part of it in the span, the
/// rows given back hold no more along the translation than the projected rows: what the
/// projection took of it stays taken. A draw has nothing to give back.
#[test]
fn the_rows_given_back_hold_a_term_in_the_span() {
    let network = Network::akutan();
    let (ns, nc) = (network.len(), 3 * network.len());
    let mut rng = StdRng::seed_from_u64(5);
    let mut normal = move || draw::normal(&mut rng);
    let scale = vec![1.0; nc];
    let up = translation(&scale, ns, 2);
    // Span columns without a translation's part, but for the last, which holds the upward one.
    let translations = translation_basis(&scale, ns);
    let mut columns: Vec<(Vec<f64>, f64)> = (0..SOURCE_VARIABLES)
        .map(|_| {
            let col: Vec<f64> = (0..nc).map(|_| normal()).collect();
            (project(&translations, &col), 1.0)
        })
        .collect();
    for (v, u) in columns[SOURCE_VARIABLES - 1].0.iter_mut().zip(&up) {
        *v += u;
    }
    let w = std::f64::consts::TAU / 365.25;
    let days: Vec<f64> = (0..3000).map(|t| t as f64).collect();
    let rows: Vec<Vec<f64>> = days
        .iter()
        .map(|d| {
            let (s, c) = ((w * d).sin(), (w * d).cos());
            (0..nc)
                .map(|k| 2.0 * s * columns[0].0[k] + 1.5 * c * up[k] + 0.5 * normal())
                .collect()
        })
        .collect();
    let shared = plain(&network, &scale, &days);
    let res = view(&shared, &rows, orthonormal(&columns, 1e-9, 1));
    let fitted = |r: &[f64]| annual(r, &days, nc);
    let back = res.given_back().expect("the data's own residuals");
    assert_eq!(back.days, res.fit.days);
    let (got, lost) = (fitted(&back.r), fitted(&res.fit.r));
    for c in 0..nc {
        let want = 2.0 * columns[0].0[c];
        assert!(
            (got[c][1] - want).abs() < 0.05,
            "channel {c}: {got:?} vs {want}"
        );
        assert!(
            lost[c][1].abs() < 0.05,
            "channel {c}: {lost:?} left after projection"
        );
    }
    // The translation's cosine: as much of it along the upward translation in both (what of it
    // the projection took stays taken), less than it had.
    let along_up = |f: &[Vec<f64>]| (2 * ns..nc).map(|c| f[c][2]).sum::<f64>() / ns as f64;
    let (kept, projected) = (along_up(&got), along_up(&lost));
    assert!((kept - projected).abs() < 1e-9, "{kept} vs {projected}");
    assert!(kept < 1.4, "the translation given back: {kept}");
    assert!(res.with_fit(res.fit.r.clone()).given_back().is_none());
}

/// With the common mode declared (the translations in F's tangent), the projection takes an
/// annual network translation off whole: the rows given back whole hold it again (a station's
/// annual amplitude, whichever effect the loop declared first), the rows given back keep only
/// each station's part beside the network's. Without the common mode there is nothing more to
/// give back.
#[test]
fn the_rows_given_back_hold_a_declared_translations_annual_term() {
    let network = Network::akutan();
    let (ns, nc) = (network.len(), 3 * network.len());
    let mut rng = StdRng::seed_from_u64(6);
    let mut normal = move || draw::normal(&mut rng);
    let scale = vec![1.0; nc];
    let mut columns: Vec<(Vec<f64>, f64)> = (0..SOURCE_VARIABLES)
        .map(|_| ((0..nc).map(|_| normal()).collect(), 1.0))
        .collect();
    columns.extend((0..3).map(|k| (translation(&scale, ns, k), 1.0)));
    let w = std::f64::consts::TAU / 365.25;
    let days: Vec<f64> = (0..2000).map(|t| t as f64).collect();
    // 1.5 (east) and 3 (up) along the translations, plus a station's own annual term.
    let rows: Vec<Vec<f64>> = days
        .iter()
        .map(|d| {
            let s = (w * d).sin();
            (0..nc)
                .map(|c| match (c / ns, c % ns) {
                    (0, 0) => 2.5 * s,
                    (0, _) => 1.5 * s,
                    (2, _) => 3.0 * s,
                    _ => 0.0,
                } + 0.3 * normal())
                .collect()
        })
        .collect();
    let shared = plain(&network, &scale, &days);
    let res = view(&shared, &rows, orthonormal(&columns, 1e-9, 1));
    let fitted = |r: &[f64]| annual(r, &days, nc);
    let back = fitted(&res.given_back_whole().expect("the common mode declared").r);
    let projected = fitted(&res.given_back().expect("the data's own residuals").r);
    for c in 0..nc {
        let want = match (c / ns, c % ns) {
            (0, 0) => 2.5,
            (0, _) => 1.5,
            (2, _) => 3.0,
            _ => 0.0,
        };
        assert!(
            (back[c][1] - want).abs() < 0.05,
            "channel {c}: {} vs {want}",
            back[c][1]
        );
    }
    // Given back, the east translation's share stays taken: what is left is station 0's own
    // term less its network mean.
    let mean_east = (0..ns).map(|c| projected[c][1]).sum::<f64>() / ns as f64;
    assert!(mean_east.abs() < 0.05, "{mean_east}");
    assert!((projected[0][1] - 1.0 * (1.0 - 1.0 / ns as f64)).abs() < 0.05);
    let without = view(
        &shared,
        &rows,
        orthonormal(&columns[..SOURCE_VARIABLES], 1e-9, 1),
    );
    assert!(without.given_back_whole().is_none());
}

/// A day whose encoder put the main source deep and at its volume bound, with a network
/// translation in the data: the refit finds the source where the data put it, the translation
/// fitted beside it.
#[test]
fn a_deep_encoder_source_is_refitted_where_the_data_put_it() {
    let network = Network::akutan();
    let stations = &network.stations;
    let nc = 3 * stations.len();
    let truth = [0.3, 0.2, 7.0, 4.0];
    let mut obs = vec![0.0; nc];
    mogi::field(stations, &truth, &mut obs).unwrap();
    let shift = [1.5, -2.0, 4.0];
    for (c, o) in obs.iter_mut().enumerate() {
        *o += shift[c / stations.len()];
    }
    let encoder = [-0.5, 1.0, 13.5, 9.9];
    let mut physics = vec![0.0; nc];
    mogi::field(stations, &encoder, &mut physics).unwrap();
    let day = Day {
        obs,
        physics,
        params: encoder.to_vec(),
    };
    let common = OwnedEffect::CommonMode;
    let bytes = common.bytes();
    let effects = [common.borrow(&bytes)];
    let mut bounds = magic_core::mogi::PAPER_BOUNDS.to_vec();
    bounds.extend(crate::gnss::effect_bounds(&common));
    let scale = vec![1.0; nc];
    let pb = lsq::Problem {
        stations,
        effects: &effects,
        bounds: &bounds,
        scale: &scale,
    };
    let pos = refit(&pb, &day, 14000.0).unwrap();
    for k in 0..3 {
        assert!((pos[k] - truth[k]).abs() < 1e-3, "{pos:?} vs {truth:?}");
    }
}

/// Beside a declared extra source the span a new source must reach beyond holds its field:
/// found again, the declared source is nothing new; a source elsewhere still is.
#[test]
fn a_declared_source_found_again_is_not_a_new_source() {
    use crate::gnss::families::second_source::resolvable;
    let (network, scale, main, span) = akutan_main_source();
    let nc = scale.len();
    let declared = [main[0] - 7.0, main[1] - 1.5, 5.0];
    let mut field = vec![0.0; nc];
    let p = [declared[0], declared[1], declared[2], 1.0];
    mogi::field(&network.stations, &p, &mut field).unwrap();
    let mut columns: Vec<(Vec<f64>, f64)> = span.iter().map(|q| (q.clone(), 1.0)).collect();
    columns.push(scaled(
        field.iter().zip(&scale).map(|(v, s)| v / s).collect(),
    ));
    let rows = vec![vec![0.0; nc]; 10];
    let days: Vec<f64> = (0..rows.len()).map(|t| t as f64).collect();
    let alone = beside_main_source(&network, &scale, main, span.clone(), &rows);
    let shared = Shared {
        main,
        source_span: span,
        sources_span: orthonormal(&columns, 1e-9, 2),
        ..plain(&network, &scale, &days)
    };
    let beside = view(&shared, &rows, Vec::new());
    assert!(resolvable(&alone, declared) > 0.5);
    assert!(resolvable(&beside, declared) < 1e-6);
    let elsewhere = [main[0] + 6.0, main[1] + 5.0, 4.0];
    assert!(
        resolvable(&beside, elsewhere) > 0.5,
        "{}",
        resolvable(&beside, elsewhere)
    );
}

/// A declared source the main one trades with (its field mostly in the main source's span)
/// rejects a source across the main source from it, not one on its side; with no such declared
/// source (none, or all mostly beyond the span) neither is rejected.
#[test]
fn no_source_is_taken_across_a_declared_one_the_main_source_trades_with() {
    use crate::analysis::Rejection;
    use crate::gnss::families::second_source::{
        rejection, MIN_RESOLVABLE_DECLARED, MIN_TRADE_ANGLE_DEG,
    };
    let (network, scale, main, span) = akutan_main_source();
    let nc = scale.len();
    let rows = vec![vec![0.0; nc]; 10];
    let days: Vec<f64> = (0..rows.len()).map(|t| t as f64).collect();
    let far = [main[0] + 8.0, main[1] - 3.0, 5.0];
    let with = |trading: Vec<Trade>| {
        let shared = Shared {
            main,
            source_span: span.clone(),
            sources_span: span.clone(),
            trading,
            ..plain(&network, &scale, &days)
        };
        rejection(&view(&shared, &rows, Vec::new()), far)
    };
    let trade = |dx: f64, dy: f64| Trade {
        share: 0.4,
        at: [main[0] + dx, main[1] + dy, 3.0],
    };
    assert_eq!(with(Vec::new()), None);
    // On the candidate's side of the main source (about 4° from it): taken.
    assert_eq!(with(vec![trade(3.0, -1.0)]), None);
    // Across from it (about 177°): the trade's mirror image.
    match with(vec![trade(3.0, -1.0), trade(-3.0, 1.0)]) {
        Some(Rejection::BesideTrade {
            share,
            least,
            angle,
            least_angle,
        }) => {
            assert_eq!((share, least), (0.4, MIN_RESOLVABLE_DECLARED));
            assert_eq!(least_angle, MIN_TRADE_ANGLE_DEG);
            assert!((angle - 177.0).abs() < 1.0, "{angle}");
        }
        other => panic!("expected a rejection beside the trade, got {other:?}"),
    }
}

/// A draw that keeps a station ([`GnssResiduals::kept`]) admits only the sources that station
/// holds most of — the shallow one under
/// it, not the same deeper nor one under another station; the data admit every source.
#[test]
fn a_draw_keeping_a_station_is_searched_among_the_sources_it_holds_most_of() {
    use crate::gnss::families::held_station::held_by;
    let (network, scale, main, span) = akutan_main_source();
    let flat = vec![vec![0.0; scale.len()]; 10];
    let res = beside_main_source(&network, &scale, main, span, &flat);
    let far = |s: &magic_core::mogi::Station| (s.x_km - main[0]).hypot(s.y_km - main[1]);
    let mut by_distance: Vec<usize> = (0..network.len()).collect();
    by_distance.sort_by(|a, b| far(&network.stations[*b]).total_cmp(&far(&network.stations[*a])));
    let under = |i: usize, depth: f64| {
        let s = &network.stations[i];
        [s.x_km, s.y_km, depth]
    };
    let (i, j) = (by_distance[0], by_distance[1]);
    let mut draw = res.with_fit(res.fit.r.clone());
    draw.kept = Some(i);
    assert!(held_by(&draw, under(i, 1.25)));
    assert!(!held_by(&draw, under(i, 4.0)));
    assert!(!held_by(&draw, under(j, 1.25)));
    assert!([under(i, 4.0), under(j, 1.25)]
        .iter()
        .all(|p| held_by(&res, *p)));
}

/// A pulse one station holds most of is confirmed by the others where that station moves: the
/// others' own pulse along the same field a year later scores less than a tenth of the same
/// pulse at the same time (here 0.07: the high-pass leaves a trace of it around the station's).
#[test]
fn the_others_confirm_a_pulse_where_its_station_moves() {
    use crate::analysis::Family;
    use crate::gnss::families::second_source::{pattern, SecondSource, SourceFit};
    let (network, scale, main, span) = akutan_main_source();
    let (nc, ns) = (scale.len(), network.len());
    let far = |s: &magic_core::mogi::Station| (s.x_km - main[0]).hypot(s.y_km - main[1]);
    let (i, st) = (network.stations.iter().enumerate())
        .max_by(|a, b| far(a.1).total_cmp(&far(b.1)))
        .unwrap();
    let pos = [st.x_km, st.y_km, 1.25];
    let flat = vec![vec![0.0; nc]; 10];
    let g = pattern(
        &beside_main_source(&network, &scale, main, span.clone(), &flat),
        pos,
    );
    let mut rng = StdRng::seed_from_u64(5);
    let mut rows = |others_from: usize| -> Vec<Vec<f64>> {
        (0..900)
            .map(|t| {
                (0..nc)
                    .map(|c| {
                        let from = if c % ns == i { 200 } else { others_from };
                        let on = (from..from + 100).contains(&t) as u8 as f64;
                        on * g[c] + 0.01 * (rand::Rng::random::<f64>(&mut rng) - 0.5)
                    })
                    .collect()
            })
            .collect()
    };
    let fit = SourceFit {
        pos,
        window: 30,
        ..SourceFit::default()
    };
    let mut without = |others_from: usize| {
        let res = beside_main_source(&network, &scale, main, span.clone(), &rows(others_from));
        let h = SecondSource.held_part(&res, &fit);
        h.expect("one station holds most of the field").score
    };
    let (together, later) = (without(200), without(600));
    assert!(together > 0.01, "{together}");
    assert!(later < 0.1 * together, "{later} against {together}");
}
