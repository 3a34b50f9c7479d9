"""`magic.xarray.invert`: lazy on Dask, on a `distributed` cluster, equal to the single-process
call; the example script end to end."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import magic
import magic.xarray

from conftest import s2_spectra

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "invert_cube.py"


@pytest.fixture(scope="module")
def cube(data):
    """A (y, x, band) reflectance cube of real spectra with band labels, and a no-data pixel."""
    x, _ = s2_spectra(data, 200, ("2018.07.02", "2018.08.09"))
    bands = ["B02", "B03", "B04", "B05", "B06", "B07", "B08", "B8A", "B09", "B11", "B12"]
    c = x[:400].reshape(20, 20, 11).astype(np.float32)
    c[0, 0] = np.nan
    return xr.DataArray(c, dims=("y", "x", "band"),
                        coords={"y": np.arange(20) * 10.0, "x": np.arange(20) * 10.0,
                                "band": bands})


@pytest.fixture(scope="module")
def cluster():
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as lc, Client(lc) as client:
        yield client


def assert_dataset_equals_invert(ds: xr.Dataset, model: magic.Model, obs: np.ndarray) -> None:
    want = model.invert(obs, errors="nan")
    assert sorted(ds.data_vars) == sorted(model.outputs)
    for c in model.outputs:
        assert ds[c].dtype == want[c].dtype, c
        np.testing.assert_array_equal(ds[c].values, want[c], err_msg=c)


def test_numpy_backed(forest, cube):
    model = magic.Model.load(forest)
    ds = magic.xarray.invert(cube, model, errors="nan")
    assert list(ds.data_vars) == model.outputs
    assert ds["LAI"].dims == ("y", "x")
    np.testing.assert_array_equal(ds["x"].values, cube["x"].values)
    assert_dataset_equals_invert(ds, model, cube.values)
    assert np.isnan(ds["LAI"].values[0, 0])


def test_units_of_the_result_columns():
    units = magic.xarray.units
    assert units("depth_km") == "km" and units("cab") == "ug cm-2"
    assert units("dv_1e6m3") == units("dv3_1e6m3") == "1e6 m3"
    assert units("cm_u_mm") == "mm" and units("elev_mm_per_km") == "mm km-1"
    assert units("LAI") is None and units("N") is None


def test_bands_are_matched_by_name(forest, cube):
    model = magic.Model.load(forest)
    shuffled = cube.isel(band=list(reversed(range(11))))
    ds = magic.xarray.invert(shuffled, model, errors="nan")
    assert_dataset_equals_invert(ds, model, cube.values)
    with pytest.raises(ValueError, match=r"lacks the model's inputs \['B02'\]"):
        magic.xarray.invert(cube.isel(band=slice(1, None)), model)
    with pytest.raises(ValueError, match="no dimension 'wavelength'"):
        magic.xarray.invert(cube, model, dim="wavelength")
    with pytest.raises(TypeError, match="float32 or float64"):
        magic.xarray.invert((cube.fillna(0) * 1e4).astype(np.uint16), model)


def test_distributed_cluster_equals_single_process(forest, cube, cluster):
    model = magic.Model.load(forest)
    lazy = magic.xarray.invert(cube.chunk({"y": 5, "x": 10, "band": 4}), model, errors="nan")
    assert lazy["LAI"].chunks == ((5, 5, 5, 5), (10, 10))
    ds = lazy.compute()  # on the cluster: the Client is the default scheduler
    assert_dataset_equals_invert(ds, model, cube.values)
    # The work ran on both worker processes.
    assert len(cluster.scheduler_info()["workers"]) == 2


def test_errors_raise_from_a_task(forest, cube, cluster):
    model = magic.Model.load(forest)
    lazy = magic.xarray.invert(cube.chunk({"y": 10}), model)
    with pytest.raises(ValueError, match=r"block of shape \(10, 20\).*obs\[0, 0\]: too few"):
        lazy.compute()


def test_dates_from_a_coordinate(forest_sun, data, cluster):
    model = magic.Model.load(forest_sun)
    x, dates = s2_spectra(data, 30, ("2018.04.21", "2018.08.09"))
    t = np.array([d.replace(".", "-") for d in dates[::30]], dtype="datetime64[ns]")
    da = xr.DataArray(x.reshape(2, 30, 11), dims=("time", "site", "band"),
                      coords={"time": t, "band": model.inputs})
    ds = magic.xarray.invert(da.chunk({"site": 10}), model).compute()
    want = model.invert(x, dates=dates)
    np.testing.assert_array_equal(ds["LAI"].values.reshape(-1), want["LAI"])


def test_example_script(forest, data, tmp_path):
    out, cube_store = tmp_path / "variables.zarr", tmp_path / "cube.zarr"
    r = subprocess.run(
        [sys.executable, str(EXAMPLE), "--model", str(forest), "--tables", str(data / "rtm"),
         "--size", "48", "--chunk", "16", "--workers", "2", "--save-input", str(cube_store),
         "--out", str(out)],
        capture_output=True, text=True, timeout=600,
    )
    assert r.returncode == 0, r.stderr
    assert "2304 spectra" in r.stdout, r.stdout
    ds = xr.open_zarr(out).compute()
    assert ds["LAI"].shape == (48, 48)
    cube = xr.open_zarr(cube_store)["reflectance"].values
    assert_dataset_equals_invert(ds, magic.Model.load(forest), cube)
