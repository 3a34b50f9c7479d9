"""Every kind of bad input raises the right exception with the core's message; none crashes the
interpreter (each case runs in this process)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

import magic

from conftest import gnss_rows

INFORM_ROW = [1.5, 40, 10, 2, 0.25, 0.01, 0.01, 0.0015, 0.01, 3, 1, 5, 0.01, 0.8, 30, 0, 0,
              0.5, 4, 500, 17]


@pytest.fixture(scope="module")
def model(volcano):
    return magic.Model.load(volcano)


@pytest.fixture(scope="module")
def obs(synth):
    return gnss_rows(synth, 8)[1]


# --- wrong dtype: TypeError ------------------------------------------------------------------

@pytest.mark.parametrize("bad", [
    np.zeros((2, 36), dtype=np.int64),
    np.zeros((2, 36), dtype=np.uint16),
    np.zeros((2, 36), dtype=bool),
    np.zeros((2, 36), dtype=np.complex128),
    np.full((2, 36), "1.0"),
    np.array([[object()] * 36]),
    [[1, 2, 3] * 12],
])
def test_obs_dtype(model, bad):
    with pytest.raises(TypeError, match="obs must be"):
        model.invert(bad)


def test_forward_dtype(tables, data):
    with pytest.raises(TypeError, match="params must be"):
        magic.inform.forward(np.zeros((1, 21), dtype=np.int32), tables)
    with pytest.raises(TypeError, match="params must be"):
        magic.mogi.forward([["a", "b", "c", "d"]], data / "gnss" / "stations.json")
    with pytest.raises(TypeError):
        magic.inform.forward(np.zeros((1, 21)), "not tables")
    with pytest.raises(TypeError, match="stations must hold numbers"):
        magic.mogi.forward(np.zeros((1, 4)), np.array([["a", "b", "c"]]))


# --- wrong shapes: ValueError ----------------------------------------------------------------

@pytest.mark.parametrize("shape", [(35,), (2, 37), (2, 36, 1), ()])
def test_obs_shape(model, shape):
    with pytest.raises(ValueError, match=r"obs: .*(last axis must hold 36|0-d)"):
        model.invert(np.zeros(shape))


def test_forward_shapes(tables, data):
    stations = data / "gnss" / "stations.json"
    with pytest.raises(ValueError, match="last axis must hold 4 values"):
        magic.mogi.forward(np.zeros((3, 5)), stations)
    with pytest.raises(ValueError, match="last axis must hold 21 values"):
        magic.inform.forward(np.zeros(20), tables)
    with pytest.raises(ValueError, match="last axis must hold 14 values"):
        magic.prosail.forward(np.zeros((2, 15)), tables)
    with pytest.raises(ValueError, match=r"stations: shape \(2, 2\)"):
        magic.mogi.forward(np.zeros((1, 4)), np.zeros((2, 2)))


def test_dates_shape_and_values(forest_sun, data):
    m = magic.Model.load(forest_sun)
    x = np.full((4, 11), 0.05)
    with pytest.raises(ValueError, match="does not broadcast"):
        m.invert(x, dates=np.array(["2018-06-01"] * 3))
    with pytest.raises(ValueError, match="dates: "):
        m.invert(x, dates=["2018-13-45"] * 4)
    with pytest.raises(TypeError, match="dates must be"):
        m.invert(x, dates=np.ones(4, dtype=complex))


# --- NaN where not allowed -------------------------------------------------------------------

def test_rows_that_cannot_be_inverted(model, obs):
    x = obs.copy()
    x[3] = np.nan  # nothing observed
    with pytest.raises(ValueError, match=r"obs\[3\]: too few observed channels: 0 observed"):
        model.invert(x)
    res = model.invert(x, errors="nan")
    assert np.isnan(res["x_km"][3]) and np.isfinite(res["x_km"][[0, 1, 2, 4]]).all()
    y = obs.reshape(2, 4, 36).copy()
    y[1, 2, 5] = np.inf
    with pytest.raises(ValueError, match=r"obs\[1, 2\]: observation\[5\] is not a finite"):
        model.invert(y)
    y[1, 2, 5] = 2e4  # 20 m
    with pytest.raises(ValueError, match=r"obs\[1, 2\]: observation magnitude is out of range"):
        model.invert(y)


def test_first_bad_row_is_named(model, obs):
    x = np.tile(obs, (200, 1))
    x[[1500, 700, 1201]] = np.nan
    with pytest.raises(ValueError, match=r"obs\[700\]"):
        model.invert(x)


def test_unknown_date_where_needed(forest_sun, data):
    m = magic.Model.load(forest_sun)
    x = np.full((3, 11), 0.05)
    with pytest.raises(ValueError, match=r"obs\[0\]: .*"):
        m.invert(x)
    with pytest.raises(ValueError, match=r"obs\[1\]"):
        m.invert(x, dates=np.array(["2018-06-01", "NaT", "2018-06-03"], dtype="datetime64[D]"))
    with pytest.raises(ValueError, match=r"obs\[2\]"):
        m.invert(x, dates=[17800.0, 17801.0, np.nan])


def test_forward_nan_and_domain(tables, data):
    stations = data / "gnss" / "stations.json"
    with pytest.raises(ValueError, match=r"params\[1\]: mogi parameter\[3\] is not a finite"):
        magic.mogi.forward([[0.0, 0.0, 5.0, 1.0], [0.0, 0.0, 5.0, np.nan]], stations)
    with pytest.raises(ValueError, match=r"params\[0\]: source depth is out of range"):
        magic.mogi.forward([[0.0, 0.0, -1.0, 1.0]], stations)
    x = np.array([INFORM_ROW, INFORM_ROW])
    x[1, 9] = np.nan
    with pytest.raises(ValueError, match=r"params\[1\]: inform input\[9\] is not a finite"):
        magic.inform.forward(x, tables)
    x[1, 9] = -1
    with pytest.raises(ValueError, match=r"params\[1\]: LAI \(must be > 0\) is out of range"):
        magic.inform.forward(x, tables)
    with pytest.raises(ValueError, match="geometry"):
        magic.inform.forward(x[:1], tables, geometry="flat")
    with pytest.raises(ValueError, match=r"stations\[1\]: not a finite position"):
        magic.mogi.forward(np.zeros((1, 4)), np.array([[0, 0, 0], [np.nan, 0, 0.0]]))


def test_bad_options(model, obs, tables):
    with pytest.raises(ValueError, match="errors"):
        model.invert(obs, errors="ignore")
    with pytest.raises(ValueError, match="threads"):
        model.invert(obs, threads=0)
    with pytest.raises(OverflowError):
        model.invert(obs, threads=-1)


# --- corrupt, truncated, foreign model bytes; unreadable files -------------------------------

def test_corrupt_model_bytes(volcano):
    good = open(volcano, "rb").read()
    with pytest.raises(ValueError, match="not a magic model file"):
        magic.Model.from_bytes(b"definitely not a model")
    for n in (0, 3, 9, 14, len(good) // 2, len(good) - 1):
        with pytest.raises(ValueError, match="truncated|not a magic model"):
            magic.Model.from_bytes(good[:n])
    for pos in (12, 200, len(good) // 2, len(good) - 5):
        bad = bytearray(good)
        bad[pos] ^= 0x10
        with pytest.raises(ValueError, match="corrupt|malformed|invalid"):
            magic.Model.from_bytes(bytes(bad))
    # One byte more than the header declares: the size mismatch, with both sizes.
    with pytest.raises(ValueError, match=r"model file bytes: expected \d+, found \d+"):
        magic.Model.from_bytes(good + b"\0")
    with pytest.raises(ValueError, match="version"):
        magic.Model.from_bytes(good[:4] + b"\x63\x00" + good[6:])
    with pytest.raises(TypeError):
        magic.Model.from_bytes("a string")


def test_unreadable_model_files(tmp_path, volcano):
    with pytest.raises(FileNotFoundError, match="nothing.magic"):
        magic.Model.load(tmp_path / "nothing.magic")
    with pytest.raises(IsADirectoryError):
        magic.Model.load(tmp_path)
    bad = tmp_path / "half.magic"
    bad.write_bytes(open(volcano, "rb").read()[:100])
    with pytest.raises(ValueError, match=r"half.magic: model file is truncated"):
        magic.Model.load(bad)


def test_missing_and_broken_tables(tmp_path, data):
    with pytest.raises(FileNotFoundError, match="prospect_d_coefficients.csv"):
        magic.Tables.load(tmp_path)
    with pytest.raises(FileNotFoundError):
        magic.Tables.load(tmp_path / "no such folder")
    broken = tmp_path / "rtm"
    shutil.copytree(data / "rtm", broken)
    with pytest.raises(FileNotFoundError, match="soil_spectra.csv"):
        (broken / "soil_spectra.csv").unlink()
        magic.Tables.load(broken)
    shutil.copy(data / "rtm" / "soil_spectra.csv", broken / "soil_spectra.csv")
    text = (broken / "solar_spectra.csv").read_text().splitlines()
    (broken / "solar_spectra.csv").write_text("\n".join(text[:-300]) + "\n")
    with pytest.raises(ValueError, match="solar_spectra.csv"):
        magic.Tables.load(broken)
    (broken / "solar_spectra.csv").write_text("\n".join(text[:50] + ["400.5,abc,1"] + text[51:]))
    with pytest.raises(ValueError, match=r"solar_spectra.csv:51"):
        magic.Tables.load(broken)
