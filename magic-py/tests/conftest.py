"""Shared fixtures: the data folder, the `magic` command line, tiny models trained with it, and a
helper that runs `magic invert` on the same rows as `Model.invert`.

The data are found through `MAGIC_DATA` or `../shared/data` beside the repository; the `magic`
binary through `MAGIC_BIN` or `target/release/magic` of the workspace. Without either the tests
fail: nothing here is skipped.
"""

from __future__ import annotations

import csv
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import magic

REPO = Path(__file__).resolve().parents[2]


def data_dir() -> Path:
    d = Path(os.environ.get("MAGIC_DATA") or REPO.parent / "shared" / "data")
    missing = [s for s in ("gnss", "s2", "rtm", "oracle") if not (d / s).is_dir()]
    if missing:
        pytest.fail(
            f"data folder {d} lacks {missing}: set MAGIC_DATA to the data (gnss/, s2/, rtm/, "
            "oracle/)",
            pytrace=False,
        )
    return d


@pytest.fixture(scope="session")
def data() -> Path:
    return data_dir()


@pytest.fixture(scope="session")
def magic_bin() -> Path:
    b = Path(os.environ.get("MAGIC_BIN") or REPO / "target" / "release" / "magic")
    if not b.is_file():
        pytest.fail(
            f"no `magic` binary at {b}: run `cargo build --release -p magic-train --bin magic` "
            "or set MAGIC_BIN",
            pytrace=False,
        )
    return b


def run(cmd: list, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)


def train(magic_bin: Path, data: Path, out: Path, args: list) -> Path:
    env = dict(os.environ, MAGIC_DATA=str(data))
    r = run([magic_bin, "train", *args, "--out", out], env=env)
    assert r.returncode == 0, f"magic train {' '.join(map(str, args))} failed:\n{r.stderr}"
    return out


@pytest.fixture(scope="session")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("magic-py")


@pytest.fixture(scope="session")
def synth(magic_bin, work) -> Path:
    """A synthetic GNSS dataset (`magic synth`, 12-station network)."""
    out = work / "synth"
    r = run([magic_bin, "synth", "--scenario", "clean", "--seed", "1", "--out", out])
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="session")
def volcano(magic_bin, data, synth, work) -> Path:
    """A volcano model C trained for 2 epochs on the synthetic data."""
    return train(magic_bin, data, work / "volcano.magic",
                 ["mogi", "--variant", "C", "--data-dir", synth, "--epochs", "2"])


@pytest.fixture(scope="session")
def volcano_cm(magic_bin, data, synth, work) -> Path:
    """A volcano model B with a declared common mode (three more variables)."""
    return train(magic_bin, data, work / "volcano_cm.magic",
                 ["mogi", "--variant", "B", "--data-dir", synth, "--epochs", "1",
                  "--effects", "common_mode"])


@pytest.fixture(scope="session")
def forest(magic_bin, data, work) -> Path:
    """A forest model C trained for 1 epoch on 500 spectra of the shared S2 data."""
    return train(magic_bin, data, work / "forest.magic",
                 ["rtm", "--variant", "C", "--limit", "500", "--epochs", "1"])


@pytest.fixture(scope="session")
def forest_sun(magic_bin, data, work) -> Path:
    """A forest model B with the sun of each date declared (needs dates)."""
    return train(magic_bin, data, work / "forest_sun.magic",
                 ["rtm", "--variant", "B", "--limit", "300", "--epochs", "1",
                  "--geometry", "physical", "--effects", "illumination"])


@pytest.fixture(scope="session")
def tables(data) -> magic.Tables:
    return magic.Tables.load(data / "rtm")


def gnss_rows(synth: Path, n: int) -> tuple:
    """The first `n` rows of the synthetic test split in mm, with their dates (YYYY.MM.DD)."""
    mean = np.loadtxt(synth / "train_x_mean.csv", ndmin=1)
    scale = np.loadtxt(synth / "train_x_scale.csv", ndmin=1)
    with open(synth / "test.csv", newline="") as f:
        rd = csv.DictReader(f)
        rows = [r for _, r in zip(range(n), rd)]
        cols = [c for c in rd.fieldnames if c[:3] in ("ux_", "uy_", "uz_")]
    x = np.array([[float(r[c]) if r[c] else np.nan for c in cols] for r in rows])
    return cols, x * scale + mean, [r["date"] for r in rows]


def s2_spectra(data: Path, n_sites: int, dates: tuple) -> tuple:
    """Reflectance spectra (11 bands) of the first `n_sites` sites of the S2 extract on `dates`
    (`YYYY.MM.DD`), with their dates: arrays `(n_sites * len(dates), 11)` and the date strings."""
    bands = ["B02", "B03", "B04", "B05", "B06", "B07", "B08", "B8A", "B09", "B11", "B12"]
    with open(data / "s2" / "BPWW_extract_2018.csv", newline="") as f:
        rd = csv.reader(f, delimiter=";")
        header = next(rd)
        rows = [r for _, r in zip(range(n_sites), rd)]
    out, when = [], []
    for d in dates:
        idx = [next(i for i, h in enumerate(header) if h.startswith(f"{d}_{b}_")) for b in bands]
        for r in rows:
            out.append([float(r[i]) / 1e4 if r[i].strip() else np.nan for i in idx])
            when.append(d)
    return np.array(out), when


def cli_invert(magic_bin: Path, model: Path, names: list, obs: np.ndarray, tmp: Path,
               dates=None, extra=()) -> list:
    """`magic invert` on the rows of `obs` (columns `names`, values written exactly), with the
    options `extra`: the result rows as lists of strings (a failed row is `["error", message]`)."""
    inp, out = tmp / "obs.csv", tmp / "result.csv"
    with open(inp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow((["date"] if dates is not None else []) + list(names))
        for i, row in enumerate(obs.reshape(-1, obs.shape[-1])):
            vals = ["" if math.isnan(v) else repr(float(v)) for v in row]
            w.writerow(([dates[i]] if dates is not None else []) + vals)
    r = run([magic_bin, "invert", "--model", model, "--input", inp, "--output", out, *extra])
    assert out.is_file(), f"magic invert wrote nothing:\n{r.stderr}"
    with open(out, newline="") as f:
        lines = f.read().splitlines()
    if dates is not None:
        lines = [ln.split(",", 1)[1] for ln in lines]
    rows = [ln.split(",", 1) if ln.startswith("error,") else ln.split(",") for ln in lines[1:]]
    assert len(rows) == len(obs.reshape(-1, obs.shape[-1])), "one result row per input row"
    return lines[0].split(","), rows
