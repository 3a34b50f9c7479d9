"""Invert a Sentinel-2 reflectance cube (y, x, band) on a Dask cluster and write the forest
variables to Zarr.

    python invert_cube.py --model forest.magic --cube my_tile.zarr --out variables.zarr

`--cube` is a Zarr store or NetCDF file with a variable `reflectance` of dimensions (y, x, band)
in reflectance (0-1; divide L2A digital numbers by 10 000 first), band labels as in
`model.inputs` (`B02` ... `B12`) and NaN where there is no data. Without `--cube` a synthetic
cube is made from INFORM (`--tables`, the `rtm/` folder of the data) so the script runs as it
is. The cube is read lazily in chunks; each chunk is inverted by one task on a
`dask.distributed.LocalCluster`; the results (LAI, chlorophyll, cover, ... with residual and
flags) stream into a Zarr store. Point `Client(...)` at a real cluster to go beyond one machine.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import xarray as xr
from dask.distributed import Client, LocalCluster

import magic
import magic.xarray


def synthetic_cube(model: magic.Model, tables: magic.Tables, size: int, seed: int = 0):
    """INFORM reflectance of smooth random stands (size x size pixels), 1% no-data pixels."""
    rng = np.random.default_rng(seed)
    yy, xx = np.meshgrid(np.linspace(0, 1, size), np.linspace(0, 1, size), indexing="ij")

    def field(lo, hi):
        a, b, c, d = rng.uniform(1, 4, 4)
        u = 0.5 + 0.25 * np.sin(2 * np.pi * (a * xx + rng.random())) \
            + 0.25 * np.sin(2 * np.pi * (b * yy + c * xx * yy + d))
        return lo + (hi - lo) * np.clip(u, 0, 1)

    n, cab, cw, cm = field(1.2, 2.5), field(20, 70), field(0.005, 0.018), field(0.008, 0.03)
    lai, laiu, fc = field(0.5, 5), field(0.1, 1), field(0.2, 0.95)
    sd = 500.0
    cd = 2 * np.sqrt(fc * 1e4 / (np.pi * sd))
    h = np.exp(2.117 + 0.507 * np.log(cd))
    one = np.ones_like(n)
    params = np.stack([n, cab, 10 * one, 2 * one, 0.25 * one, cw, cm, 0.0015 * one, 0.01 * one,
                       lai, one, 5 * one, 0.01 * one, 0.8 * one, 35 * one, 5 * one, 30 * one,
                       laiu, cd, sd * one, h], axis=-1)
    bands = magic.inform.forward(params, tables, geometry="physical")
    keep = [magic.S2_BANDS.index(b) for b in model.inputs]
    refl = bands[..., keep] + rng.normal(0, 0.002, (size, size, len(keep)))
    refl[rng.random((size, size)) < 0.01] = np.nan
    return xr.DataArray(
        refl.astype(np.float32), dims=("y", "x", "band"), name="reflectance",
        coords={"y": 6e6 - 10.0 * np.arange(size), "x": 5e5 + 10.0 * np.arange(size),
                "band": list(model.inputs)},
        attrs={"units": "1", "description": "synthetic INFORM reflectance"},
    )


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="forest model file (magic train rtm)")
    p.add_argument("--cube", help="Zarr store or NetCDF file with `reflectance` (y, x, band)")
    p.add_argument("--tables", help="spectral tables for the synthetic cube "
                   "(default: $MAGIC_DATA/rtm)")
    p.add_argument("--size", type=int, default=512, help="synthetic cube: pixels per side")
    p.add_argument("--save-input", help="also write the synthetic cube to this Zarr store")
    p.add_argument("--chunk", type=int, default=256, help="chunk size in y and x (pixels)")
    p.add_argument("--workers", type=int, default=2, help="local worker processes")
    p.add_argument("--out", required=True, help="output Zarr store")
    a = p.parse_args(argv)

    model = magic.Model.load(a.model)
    chunks = {"y": a.chunk, "x": a.chunk, "band": -1}
    if a.cube:
        opener = xr.open_zarr if a.cube.endswith(".zarr") else xr.open_dataset
        cube = opener(a.cube, chunks=chunks)["reflectance"]
    else:
        tables_dir = a.tables or Path(os.environ.get("MAGIC_DATA", "../shared/data")) / "rtm"
        synth = synthetic_cube(model, magic.Tables.load(tables_dir), a.size)
        store = a.save_input or tempfile.mkdtemp(suffix=".zarr")
        synth.to_dataset().chunk(chunks).to_zarr(store, mode="w", zarr_format=2)
        cube = xr.open_zarr(store)["reflectance"]  # read lazily, chunk by chunk, as a real tile

    with LocalCluster(n_workers=a.workers, threads_per_worker=1,
                      dashboard_address=None) as cluster, Client(cluster):
        result = magic.xarray.invert(cube, model, dim="band", errors="nan", threads=1)
        t0 = time.perf_counter()
        result.to_zarr(a.out, mode="w", zarr_format=2)  # the graph runs here, on the cluster
        dt = time.perf_counter() - t0

    n = cube.sizes["y"] * cube.sizes["x"]
    out = xr.open_zarr(a.out)
    lai = out["LAI"].values
    print(f"{n} spectra in {dt:.1f} s ({n / dt:,.0f} per s, {a.workers} workers) -> {a.out}")
    print(f"LAI: median {np.nanmedian(lai):.2f}, 5-95% {np.nanpercentile(lai, 5):.2f}-"
          f"{np.nanpercentile(lai, 95):.2f}; no-data pixels {int(np.isnan(lai).sum())}; "
          f"flagged at a bound {int((out['flags'].values & 1).astype(bool).sum())}")


if __name__ == "__main__":
    main()
