"""The forward models from Python against the reference outputs in `oracle/`.

Tolerances are the measured agreement (the core's own oracle tests report the same figures) with
a margin of about 10x; float32 input is converted to float64 and computed in float64.
"""

from __future__ import annotations

import csv
import pickle

import numpy as np
import pytest

import magic

#: Mogi, f64, max abs error in mm (measured 1.4e-13).
MOGI_TOL_MM = 1e-12
#: INFORM, f64, max abs reflectance error against the paper implementation (measured 5.3e-14).
INFORM_TOL = 1e-12
#: PROSAIL against the `prosail` package's 4SAIL (measured 9.1e-14).
PROSAIL_TOL = 1e-12


def read_csv(path):
    with open(path, newline="") as f:
        rd = csv.DictReader(f)
        rows = list(rd)
    return rd.fieldnames, rows


def columns(rows, names):
    return np.array([[float(r[n]) for n in names] for r in rows])


def test_mogi_matches_oracle(data):
    header, rows = read_csv(data / "oracle" / "mogi_oracle_1k.csv")
    params = columns(rows, ["xcen_km", "ycen_km", "d_km", "dV_1e6m3"])
    want = columns(rows, [h for h in header if h[:3] in ("ux_", "uy_", "uz_")])
    got = magic.mogi.forward(params, data / "gnss" / "stations.json")
    assert got.shape == (len(rows), 36)
    err = np.abs(got - want).max()
    print(f"mogi_oracle_1k.csv: max |error| {err:.3e} mm")
    assert err <= MOGI_TOL_MM
    # Any leading shape; float32 parameters; the stations as a mapping or an array.
    g = magic.mogi.forward(params.reshape(10, 100, 4), data / "gnss" / "stations.json")
    np.testing.assert_array_equal(g.reshape(-1, 36), got)
    positions = magic.mogi.station_positions(data / "gnss" / "stations.json")
    np.testing.assert_array_equal(magic.mogi.forward(params, positions), got)
    p32 = params.astype(np.float32)
    np.testing.assert_array_equal(magic.mogi.forward(p32, positions),
                                  magic.mogi.forward(p32.astype(np.float64), positions))


def test_inform_matches_oracle(data, tables):
    header, rows = read_csv(data / "oracle" / "rtm_inform_s2_10k.csv")
    params = columns(rows, list(magic.inform.INPUTS))
    want = columns(rows, list(magic.S2_BANDS))
    got = magic.inform.forward(params, tables, geometry="reference")
    assert got.shape == (len(rows), 13)
    err = np.abs(got - want).max()
    print(f"rtm_inform_s2_10k.csv (reference geometry): max |error| {err:.3e}")
    assert err <= INFORM_TOL
    # The geometries differ (the reference hands INFORM cosines as angles).
    phys = magic.inform.forward(params[:50], tables)
    assert np.abs(phys - got[:50]).max() > 1e-3


def test_prosail_matches_oracle(data, tables):
    header, rows = read_csv(data / "oracle" / "sail_4sail_s2_1k.csv")
    params = columns(rows, list(magic.prosail.INPUTS))
    got = magic.prosail.forward(params, tables)
    assert got.shape == (len(rows), 4, 13)
    assert magic.prosail.FACTORS == ("rsot", "rdot", "rsdt", "rddt")
    # The file's `rdot_*` and `rddt_*` columns are swapped (the package returns rsot, rddt,
    # rsdt, rdot and the columns were labelled in the order rsot, rdot, rsdt, rddt).
    file_column = {"rsot": "rsot", "rdot": "rddt", "rsdt": "rsdt", "rddt": "rdot"}
    for k, f in enumerate(magic.prosail.FACTORS):
        want = columns(rows, [f"{file_column[f]}_{b}" for b in magic.S2_BANDS])
        err = np.abs(got[:, k] - want).max()
        print(f"sail_4sail_s2_1k.csv {f}: max |error| {err:.3e}")
        assert err <= PROSAIL_TOL, f


def test_tables_pickle_and_describe(tables):
    assert len(tables) == 2101
    again = pickle.loads(pickle.dumps(tables))
    x = np.array([[1.5, 40, 8, 0, 0.1, 0.01, 0.009, 3, 57, 0.05, 30, 0, 0, 0.5]])
    np.testing.assert_array_equal(magic.prosail.forward(x, again),
                                  magic.prosail.forward(x, tables))
    assert "2101" in repr(tables)


def test_nan_rows_with_errors_nan(data, tables):
    x = np.array([[1.5, 40, 8, 0, 0.1, 0.01, 0.009, 3, 57, 0.05, 30, 0, 0, 0.5]] * 3)
    x[1, 7] = np.nan
    with pytest.raises(ValueError, match=r"params\[1\]: prosail input\[7\] is not a finite number"):
        magic.prosail.forward(x, tables)
    y = magic.prosail.forward(x, tables, errors="nan")
    assert np.isnan(y[1]).all() and np.isfinite(y[[0, 2]]).all()
