#!/usr/bin/env python3
"""A matched-filter search for a lasting change, on the residual series `magic` writes.

Reads folders written by `magic residuals --series DIR` or `magic synth-check --series DIR`
(`residuals.csv`, `grid.csv`, and `truth.json` for a synthetic run) and searches each for a
source whose volume changes along a ramp and then stays, as the `lasting_source` family does,
with another statistic: generalised least squares under a noise model fitted to the residuals.

- Noise: per channel white noise plus a stationary AR(1), fitted to the residuals' structure
  functions at lags 1–512 days (robust: the smallest 95 % of the squared differences); the
  shape (persistence, AR over white variance) shared by every channel, fitted to their median,
  each channel's level its own.
- Statistic: for each grid point and onset (every STEP days, EDGE days from the record's ends),
  the change along a ramp of RAMP days, whitened by the fitted model (Kalman innovations) beside
  each channel's mean, amplitude free: |z|, a standard normal under the fitted model.
- Chance level: the QUANTILE (95 %) quantile of the largest |z| over the same grid and onsets in
  NULLS records simulated under the fitted model.
- The best fit is rejected on the grid's bound (as `magic` rejects a point source there).
- Synthetic runs: found when the best |z| exceeds its chance level off the bound, within 2 km
  (horizontally) of the injected source.

An experiment, not part of `magic`: docs/matched-filter.md says what it measured.
Needs numpy. Usage: scripts/lasting_matched_filter.py DIR [DIR …] (a folder holding
`residuals.csv`, or one holding such folders).
"""
import argparse
import csv
import json
import math
import os
import sys
from collections import defaultdict

import numpy as np

MAX_DISTANCE_KM = 2.0
# A fit this close to the search grid's bounding box is on its bound, rejected (as `magic`'s
# point-source families reject theirs): a source the grid would have to reach beyond.
BOUND_KM = 0.05


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if len(rows) < 2:
        sys.exit(f"{path}: no rows")
    return rows[0], rows[1:]


def read_series(d):
    head, rows = read_csv(os.path.join(d, "residuals.csv"))
    if head[0] != "date":
        sys.exit(f"{d}/residuals.csv, line 1, column 1: expected `date`, found `{head[0]}`")
    dates = [r[0] for r in rows]
    r = numbers(f"{d}/residuals.csv", rows, 1)
    ghead, grows = read_csv(os.path.join(d, "grid.csv"))
    if ghead[3:] != head[1:]:
        sys.exit(f"{d}/grid.csv, line 1: its channels are not residuals.csv's")
    g = numbers(f"{d}/grid.csv", grows, 0)
    return dates, r, g[:, :3], g[:, 3:]


def numbers(path, rows, first):
    """The rows' cells from column `first` on as floats; a bad cell exits naming its place."""
    out = np.empty((len(rows), len(rows[0]) - first))
    for i, row in enumerate(rows):
        if len(row) != len(rows[0]):
            sys.exit(f"{path}, line {i + 2}: {len(row)} cells, the first row has {len(rows[0])}")
        for j, v in enumerate(row[first:]):
            try:
                out[i, j] = float(v)
            except ValueError:
                sys.exit(f"{path}, line {i + 2}, column {j + first + 1}: `{v}` is not a number")
    return out


def structure(r, lag):
    """Robust mean squared difference at `lag` (smallest 95 %, scaled to a Gaussian's mean)."""
    d = np.sort((r[lag:] - r[:-lag]) ** 2, axis=0)
    return d[: int(0.95 * len(d))].mean(axis=0) / 0.7588


LAGS = np.array([1, 2, 4, 8, 16, 32, 64, 128, 256, 512])


def fit_noise(r):
    """White plus AR(1) per channel, one shape for all: the persistence `phi` and the AR
    variance over the white `rho`, fitted to the median over channels of each channel's
    structure function over its value at lag 1; each channel's white level from its lag 1."""
    lags = LAGS[LAGS < r.shape[0] // 4]
    d = np.array([structure(r, int(lag)) for lag in lags])  # lags x channels
    shape = np.median(d / d[0][None, :], axis=1)
    best = (np.inf, 0.0, 0.0)
    for phi in 1.0 - np.logspace(-4, -0.5, 120):
        for rho in np.logspace(-2, 3, 200):
            model = (2 + 2 * rho * (1 - phi ** lags)) / (2 + 2 * rho * (1 - phi))
            err = float(((np.log(model) - np.log(shape)) ** 2).sum())
            if err < best[0]:
                best = (err, phi, rho)
    _, phi, rho = best
    white = d[0] / (2 + 2 * rho * (1 - phi))
    return phi, rho, np.maximum(white, 1e-12)


def whiten(x, phi, rho):
    """Innovations of x (rows: days) under unit white noise plus a stationary AR(1) of
    persistence phi and variance rho, each divided by its standard deviation (Kalman filter)."""
    n = x.shape[0]
    q = rho * (1 - phi * phi)
    y = np.empty_like(x, dtype=float)
    state = np.zeros(x.shape[1:])
    p = rho
    for i in range(n):
        if i:
            p = phi * phi * p + q
            state = phi * state
        f = p + 1.0
        v = x[i] - state
        y[i] = v / math.sqrt(f)
        k = p / f
        state = state + k * v
        p = (1 - k) * p
    return y


def search(dates, r, pats, args, seed):
    n, nc = r.shape
    phi, rho, level = fit_noise(r)
    onsets = np.arange(args.edge, n - args.edge + 1, args.step)
    t = np.arange(n)[:, None]
    ramps = np.clip((t - onsets[None, :]) / args.ramp, 0.0, 1.0)
    ones = whiten(np.ones((n, 1)), phi, rho)[:, 0]
    off = lambda w: w - np.outer(ones, ones @ w) / (ones @ ones)  # noqa: E731
    yw = off(whiten(r / np.sqrt(level), phi, rho))
    gw = off(whiten(ramps, phi, rho))
    qg = (gw * gw).sum(axis=0)
    p = pats / np.sqrt(level)[None, :]
    denom = np.sqrt((p * p).sum(axis=1)[:, None] * qg[None, :])
    denom[denom == 0] = np.inf
    z = np.abs(p @ (gw.T @ yw).T) / denom
    best = np.unravel_index(np.argmax(z), z.shape)
    rng = np.random.default_rng(seed)
    null = [
        (np.abs(p @ (gw.T @ rng.standard_normal((n, nc))).T) / denom).max()
        for _ in range(args.nulls)
    ]
    chance = float(np.quantile(null, args.quantile))
    noise = f"phi {phi:.4f}, rho {rho:.3g}; null 95 %/99 % {np.quantile(null, 0.95):.2f}/{np.quantile(null, 0.99):.2f}"
    return float(z[best]), chance, best[0], dates[onsets[best[1]]], noise


def folders(paths):
    for p in paths:
        if os.path.exists(os.path.join(p, "residuals.csv")):
            yield p
        else:
            for q in sorted(os.listdir(p)):
                if os.path.exists(os.path.join(p, q, "residuals.csv")):
                    yield os.path.join(p, q)


def lasting_truth(d):
    path = os.path.join(d, "truth.json")
    if not os.path.exists(path):
        return None, None
    t = json.load(open(path))
    group = f"{t['scenario']} {t['noise']} {t['placement']}"
    for e in t.get("effects", []):
        if e["family"] == "lasting_source":
            return group, e["params"]
    return group, {}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dirs", nargs="+")
    ap.add_argument("--ramp", type=int, default=90, help="ramp length (days)")
    ap.add_argument("--step", type=int, default=10, help="days between onsets")
    ap.add_argument("--edge", type=int, default=60, help="days from the ends to the first/last onset")
    ap.add_argument("--nulls", type=int, default=100, help="simulated records for the chance level")
    ap.add_argument("--quantile", type=float, default=0.95, help="the chance level's quantile of the null's max |z|")
    args = ap.parse_args()
    tally = defaultdict(lambda: [0, 0])
    for i, d in enumerate(folders(args.dirs)):
        dates, r, pts, pats = read_series(d)
        z, chance, k, onset, noise = search(dates, r, pats, args, i)
        x, y, depth = pts[k]
        bound = bool(np.any((pts[k] - pts.min(axis=0) < BOUND_KM) | (pts.max(axis=0) - pts[k] < BOUND_KM)))
        group, truth = lasting_truth(d)
        line = f"{os.path.basename(d)}: |z| {z:.2f}, chance {chance:.2f}, at ({x:g}, {y:g}, {depth:g}) km from {onset}"
        line += ", on the grid's bound" if bound else ""
        if group is not None:
            if truth:
                dist = math.hypot(x - truth["x_km"], y - truth["y_km"])
                ok = z > chance and not bound and dist <= MAX_DISTANCE_KM
                line += f"; truth ({truth['x_km']}, {truth['y_km']}, {truth['depth_km']}) from {truth['start']}, {dist:.1f} km off: {'found' if ok else 'missed'}"
            else:
                ok = z > chance and not bound
                line += f": {'false' if ok else 'none'}"
            tally[group][0] += ok
            tally[group][1] += 1
        print(line + f" (noise: {noise})", flush=True)
    if tally:
        print("\n| runs | found (lasting injected) or false (none injected) |\n|---|---|")
        for g, (k, n) in sorted(tally.items()):
            print(f"| {g} | {k}/{n} |")


if __name__ == "__main__":
    main()
