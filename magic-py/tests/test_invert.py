"""`Model.invert` against `magic invert` on the same rows, and the Model's description."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import magic

from conftest import cli_invert, gnss_rows, s2_spectra

#: Agreement with `magic invert`, relative (the core path is the same; what is left is the CSV's
#: printing).
REL_TOL = 1e-6
#: `magic invert` prints 6 decimals: its numbers are the exact ones to within half a unit of the
#: sixth decimal.
PRINT_TOL = 0.5e-6

S2_DATES = ("2018.04.21", "2018.07.02", "2018.08.09")


def assert_same_as_cli(model: magic.Model, result: dict, header: list, rows: list) -> int:
    """Every column of `result` (flattened) equals the CLI's rows; returns the rows compared."""
    assert header == model.outputs
    flat = {k: v.reshape(-1) for k, v in result.items()}
    compared = 0
    for i, row in enumerate(rows):
        if row[0] == "error":
            assert all(np.isnan(flat[c][i]) for c in model.outputs[:-2]), (i, row)
            continue
        assert len(row) == len(header), row
        for c, text in zip(header, row):
            py = flat[c][i]
            if c in ("flags", "stations_used"):
                assert int(text) == int(py), (i, c, text, py)
                continue
            cli = float(text)
            assert abs(py - cli) <= REL_TOL * abs(cli) + PRINT_TOL, (i, c, cli, py)
            # And printed as the CLI prints it, the same text.
            assert f"{py:.6f}" == text, (i, c, text, py)
        compared += 1
    return compared


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_volcano_equals_cli(magic_bin, volcano, synth, tmp_path, dtype):
    model = magic.Model.load(volcano)
    names, x, _ = gnss_rows(synth, 400)
    assert names == model.inputs
    x = x.astype(dtype)
    # Stations down on some days (a missing channel is NaN; the CLI reads an empty field).
    x[::7, 0:3] = np.nan
    x[5::11, [4, 16, 28]] = np.nan
    header, rows = cli_invert(magic_bin, volcano, model.inputs, x, tmp_path)
    res = model.invert(x.reshape(20, 20, -1))
    assert all(v.shape == (20, 20) for v in res.values())
    assert res["flags"].dtype == np.uint8 and res["stations_used"].dtype == np.uint32
    assert assert_same_as_cli(model, res, header, rows) == 400
    assert (res["flags"].reshape(-1)[::7] & 2).all()


#: The standard deviations: the CLI prints them as the shortest f32 text (about 7 digits).
SD_REL_TOL = 1e-6


@pytest.mark.parametrize("which", ["volcano", "forest"])
def test_standard_deviations_equal_cli(magic_bin, volcano, forest, synth, data, tmp_path, which):
    path = volcano if which == "volcano" else forest
    model = magic.Model.load(path)
    if which == "volcano":
        _, x, _ = gnss_rows(synth, 80)
        x[::9, 0:3] = np.nan
    else:
        x, _ = s2_spectra(data, 30, S2_DATES)
    header, rows = cli_invert(magic_bin, path, model.inputs, x, tmp_path, extra=["--sd"])
    variables = model.outputs[:-3]
    sds = [f"{v}_sd" for v in variables]
    assert header == model.outputs + sds
    res = model.invert(x, sd=True)
    assert set(res) == set(model.outputs) | set(sds)
    plain = model.invert(x)
    compared = 0
    for i, row in enumerate(rows):
        if row[0] == "error":
            assert all(np.isnan(res[c][i]) for c in sds)
            continue
        for c in model.outputs:
            assert res[c][i] == plain[c][i] or (np.isnan(res[c][i]) and np.isnan(plain[c][i]))
        for c, text in zip(sds, row[len(model.outputs):]):
            cli = float(text)
            assert res[c][i] > 0 and abs(res[c][i] - cli) <= SD_REL_TOL * cli, (i, c, cli, res[c][i])
        compared += 1
    assert compared >= 60


def test_volcano_with_effect_names_its_variables(magic_bin, volcano_cm, synth, tmp_path):
    model = magic.Model.load(volcano_cm)
    assert model.outputs[:7] == ["x_km", "y_km", "depth_km", "dv_1e6m3",
                                 "cm_e_mm", "cm_n_mm", "cm_u_mm"]
    assert list(model.bounds) == model.outputs[:7]
    _, x, _ = gnss_rows(synth, 60)
    header, rows = cli_invert(magic_bin, volcano_cm, model.inputs, x, tmp_path)
    assert assert_same_as_cli(model, model.invert(x), header, rows) == 60


def test_forest_equals_cli(magic_bin, forest, data, tmp_path):
    model = magic.Model.load(forest)
    assert model.problem == "rtm" and model.variant == "C"
    assert model.inputs == ["B02", "B03", "B04", "B05", "B06", "B07", "B08", "B8A", "B09",
                            "B11", "B12"]
    assert model.outputs == ["N", "cab", "cw", "cm", "LAI", "LAIu", "fc", "cd", "h",
                             "residual_rms", "flags", "stations_used"]
    x, _ = s2_spectra(data, 150, S2_DATES)
    x[3::17, 8] = np.nan  # a band missing
    x[40] = np.nan  # a pixel with no data: an error row in both
    header, rows = cli_invert(magic_bin, forest, model.inputs, x, tmp_path)
    assert rows[40][0] == "error"
    with pytest.raises(ValueError, match=r"obs\[40\]: too few observed channels"):
        model.invert(x)
    res = model.invert(x, errors="nan")
    assert assert_same_as_cli(model, res, header, rows) == len(x) - 1
    assert res["flags"][40] == 0 and res["stations_used"][40] == 0


def test_forest_with_dates_equals_cli(magic_bin, forest_sun, data, tmp_path):
    model = magic.Model.load(forest_sun)
    assert model.needs_time
    x, dates = s2_spectra(data, 60, S2_DATES)
    header, rows = cli_invert(magic_bin, forest_sun, model.inputs, x, tmp_path, dates=dates)
    res = model.invert(x, dates=dates)
    assert assert_same_as_cli(model, res, header, rows) == len(x)
    # The same dates as datetime64 and as day numbers.
    d64 = np.array([d.replace(".", "-") for d in dates], dtype="datetime64[D]")
    for d in (d64, d64.astype(np.int64)):
        again = model.invert(x, dates=d)
        for c in model.outputs:
            np.testing.assert_array_equal(again[c], res[c])
    # One date per site column, broadcast over the sites.
    cube = x.reshape(len(S2_DATES), 60, -1)
    per_date = model.invert(cube, dates=d64.reshape(len(S2_DATES), 60)[:, :1])
    np.testing.assert_array_equal(per_date["LAI"].reshape(-1), res["LAI"])


def test_threads_and_layout_do_not_change_numbers(forest, data):
    model = magic.Model.load(forest)
    x, _ = s2_spectra(data, 100, S2_DATES[:2])
    a = model.invert(x)
    b = model.invert(x, threads=1)
    # A non-contiguous view (every other band of a wider array) reads the same values.
    wide = np.zeros((len(x), 2 * x.shape[1]))
    wide[:, ::2] = x
    c = model.invert(wide[:, ::2])
    for k in model.outputs:
        np.testing.assert_array_equal(a[k], b[k])
        np.testing.assert_array_equal(a[k], c[k])


def test_description_and_pickle(volcano, forest):
    v = magic.Model.load(volcano)
    assert v.problem == "mogi" and v.variant == "C" and not v.needs_time
    assert v.outputs == ["x_km", "y_km", "depth_km", "dv_1e6m3", "residual_rms", "flags",
                         "stations_used"]
    assert len(v.inputs) == 36 and v.inputs[0].startswith("ux_")
    assert set(v.bounds) == {"x_km", "y_km", "depth_km", "dv_1e6m3"}
    lo, hi = v.bounds["depth_km"]
    assert 0 < lo < hi
    f = magic.Model.load(forest)
    assert set(f.bounds) == {"N", "cab", "cw", "cm", "LAI", "LAIu", "fc"}
    for m in (v, f):
        again = pickle.loads(pickle.dumps(m))
        assert isinstance(again, magic.Model)
        assert again.to_bytes() == m.to_bytes() and again.outputs == m.outputs
    assert magic.Model.from_bytes(v.to_bytes()).inputs == v.inputs
    assert "mogi" in repr(v)


def test_empty_and_single_rows(volcano, synth):
    model = magic.Model.load(volcano)
    _, x, _ = gnss_rows(synth, 3)
    one = model.invert(x[0])
    assert all(v.shape == () for v in one.values())
    assert one["depth_km"] == model.invert(x)["depth_km"][0]
    none = model.invert(np.zeros((0, 5, 36)))
    assert all(v.shape == (0, 5) for v in none.values())
