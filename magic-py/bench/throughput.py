"""Throughput of the Python package, measured in one run (a benchmark, not a test).

    python bench/throughput.py --model forest.magic [--n 4000000] [--workers 2]

1. A forest model (INFORM, variant C) inverting Sentinel-2 spectra through ``Model.invert`` on
   every core, and on one core (``threads=1``).
2. The same spectra as a chunked (y, x, band) Zarr cube through ``magic.xarray.invert`` on a
   ``dask.distributed.LocalCluster`` (``--workers`` processes, one thread each), read, inverted
   and written back to Zarr.
3. INFORM and PROSAIL forward per spectrum from Python (batched, and one spectrum per call), and
   the ``prosail`` package's ``run_prosail`` per spectrum in the same process when it is
   importable (install it into a throwaway environment, e.g. ``python -m venv --system-site-packages
   /tmp/bench && /tmp/bench/bin/pip install prosail``, and run this script with that Python).

The spectra are the S2 data's real spectra (``$MAGIC_DATA/s2``) repeated with 1 % multiplicative
noise up to ``--n``. Without ``--model`` a model is trained with ``magic train rtm --epochs 1``
(the same network sizes as a fully trained one, so the same cost per spectrum).
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import xarray as xr

import magic
import magic.xarray

BANDS = ["B02", "B03", "B04", "B05", "B06", "B07", "B08", "B8A", "B09", "B11", "B12"]


def s2_spectra(data: Path) -> np.ndarray:
    """Every spectrum of the S2 extract (sites x dates) in reflectance, (n, 11)."""
    with open(data / "s2" / "BPWW_extract_2018.csv", newline="") as f:
        rd = csv.reader(f, delimiter=";")
        header = next(rd)
        rows = list(rd)
    dates = sorted({h[:10] for h in header if h[:4] == "2018"})
    out = []
    for d in dates:
        idx = [next(i for i, h in enumerate(header) if h.startswith(f"{d}_{b}_")) for b in BANDS]
        out.extend([[float(r[i]) / 1e4 for i in idx] for r in rows])
    return np.array(out)


def timed(f, *a, **k):
    t = time.perf_counter()
    r = f(*a, **k)
    return r, time.perf_counter() - t


def cpu_timed(f, *a, **k):
    """Result, wall-clock seconds and CPU seconds of this process (all its threads): on a
    shared machine the CPU time per spectrum is the cost, the wall clock what was obtained."""
    c = time.process_time()
    r, t = timed(f, *a, **k)
    return r, t, time.process_time() - c


def worker_cpu_seconds() -> float:
    import resource  # noqa: PLC0415

    u = resource.getrusage(resource.RUSAGE_SELF)
    return u.ru_utime + u.ru_stime


def inform_params(n: int, rng) -> np.ndarray:
    """Random INFORM inputs over the paper's box (the learned variables uniform, the others at
    the training values, physical geometry with the sun at 30 degrees)."""
    lo = np.array([1.0, 10, 0.001, 0.005, 0.01, 0.01, 0.1])
    hi = np.array([3.0, 80, 0.02, 0.05, 5.0, 1.0, 1.0])
    z = lo + (hi - lo) * rng.random((n, 7))
    n_, cab, cw, cm, lai, laiu, fc = z.T
    sd = 500.0
    cd = 2 * np.sqrt(fc * 1e4 / (np.pi * sd))
    h = np.exp(2.117 + 0.507 * np.log(cd))
    one = np.ones(n)
    return np.stack([n_, cab, 10 * one, 2 * one, 0.25 * one, cw, cm, 0.0015 * one, 0.01 * one,
                     lai, one, 5 * one, 0.01 * one, 0.8 * one, 30 * one, 0 * one, 0 * one,
                     laiu, cd, sd * one, h], axis=-1)


def prosail_params(n: int, rng) -> np.ndarray:
    u = rng.random((n, 14))
    lo = np.array([1.0, 10, 2, 0, 0, 0.002, 0.002, 0.2, 20, 0.01, 20, 0, 0, 0])
    hi = np.array([2.5, 80, 15, 3, 1, 0.03, 0.03, 6, 75, 0.2, 60, 15, 180, 1])
    return lo + (hi - lo) * u


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", help="forest model file (default: train one with --magic-bin)")
    p.add_argument("--magic-bin", default=str(Path(__file__).resolve().parents[2] / "target"
                                              / "release" / "magic"))
    p.add_argument("--data", default=os.environ.get("MAGIC_DATA", "../shared/data"))
    p.add_argument("--n", type=int, default=4_000_000, help="spectra for the inversion runs")
    p.add_argument("--one-core-n", type=int, default=100_000,
                   help="spectra for the one-core inversion run")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--chunk", type=int, default=500, help="Dask chunk: pixels per side")
    p.add_argument("--forward-n", type=int, default=4000, help="spectra per forward run")
    p.add_argument("--calls", type=int, default=300, help="single-spectrum calls per forward")
    p.add_argument("--tmp", default=None, help="scratch folder for the Zarr stores")
    a = p.parse_args(argv)
    data = Path(a.data)
    tmp = Path(a.tmp or tempfile.mkdtemp(prefix="magic-bench-"))
    tmp.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    print(f"# magic {magic.__version__}, numpy {np.__version__}, Python "
          f"{platform.python_version()}, {os.cpu_count()} cores ({platform.machine()})")

    model_path = a.model
    if model_path is None:
        model_path = str(tmp / "forest.magic")
        r = subprocess.run([a.magic_bin, "train", "rtm", "--variant", "C", "--epochs", "1",
                            "--limit", "500", "--out", model_path],
                           env=dict(os.environ, MAGIC_DATA=str(data)),
                           capture_output=True, text=True)
        if r.returncode:
            raise SystemExit(f"magic train failed:\n{r.stderr}")
    model = magic.Model.load(model_path)
    print(f"model: {model!r}")

    # -- spectra --------------------------------------------------------------------------
    base = s2_spectra(data)
    side = int(np.sqrt(a.n))
    n = side * side
    reps = -(-n // len(base))
    x = np.tile(base, (reps, 1))[:n]
    x = (x * (1 + 0.01 * rng.standard_normal(x.shape))).astype(np.float32)
    print(f"spectra: {n:,} ({side} x {side}; {len(base):,} real S2 spectra with 1 % noise)")

    # -- 1. Model.invert ------------------------------------------------------------------
    m1 = min(a.one_core_n, n)
    print(f"load average before: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    _, t1, c1 = cpu_timed(model.invert, x[:m1], threads=1)
    one_core = m1 / t1
    print(f"Model.invert, 1 thread:      {m1:>10,} spectra in {t1:8.1f} s = {one_core:10,.0f}/s "
          f"({1e6 / one_core:.0f} us per spectrum; CPU {1e6 * c1 / m1:.0f} us per spectrum)")
    res, t_all, c_all = cpu_timed(model.invert, x)
    rate_all = n / t_all
    print(f"Model.invert, all cores:     {n:>10,} spectra in {t_all:8.1f} s = {rate_all:10,.0f}/s "
          f"({rate_all / one_core:.2f}x one thread; CPU {1e6 * c_all / n:.0f} us per spectrum)")
    flagged = int((res["flags"] & 4).astype(bool).sum())
    print(f"   (LAI median {np.median(res['LAI']):.2f}; residual above threshold: {flagged:,})")
    del res

    # -- 2. Dask distributed ----------------------------------------------------------------
    from dask.distributed import Client, LocalCluster

    cube_store, out_store = tmp / "cube.zarr", tmp / "out.zarr"
    cube = xr.DataArray(x.reshape(side, side, 11), dims=("y", "x", "band"), name="reflectance",
                        coords={"band": BANDS})
    chunks = {"y": a.chunk, "x": a.chunk, "band": -1}
    cube.to_dataset().chunk(chunks).to_zarr(cube_store, mode="w", zarr_format=2)
    del cube
    with LocalCluster(n_workers=a.workers, threads_per_worker=1, dashboard_address=None) as lc, \
            Client(lc):
        lazy = xr.open_zarr(cube_store)["reflectance"]
        n_tasks = len(lazy.data.to_delayed().ravel())
        ds = magic.xarray.invert(lazy, model, threads=1)
        client = Client.current()
        before = sum(client.run(worker_cpu_seconds).values())
        _, t_dask = timed(ds.to_zarr, out_store, mode="w", zarr_format=2)
        c_dask = sum(client.run(worker_cpu_seconds).values()) - before
    rate_dask = n / t_dask
    print(f"xarray on LocalCluster({a.workers} workers x 1 thread), Zarr in -> Zarr out: "
          f"{n:,} spectra in {t_dask:.1f} s = {rate_dask:,.0f}/s "
          f"({n_tasks} chunks of {a.chunk}x{a.chunk}; "
          f"{rate_dask / (a.workers * one_core):.0%} of {a.workers}x one thread; "
          f"workers' CPU {1e6 * c_dask / n:.0f} us per spectrum)")
    print(f"load average after: {os.getloadavg()[0]:.1f}")
    check = xr.open_zarr(out_store)["LAI"].values.reshape(-1)[:m1]
    np.testing.assert_array_equal(check, model.invert(x[:m1])["LAI"])
    shutil.rmtree(cube_store)
    shutil.rmtree(out_store)

    # -- 3. forward models per spectrum -----------------------------------------------------
    tables = magic.Tables.load(data / "rtm")
    pi = inform_params(a.forward_n, rng)
    _, t, c = cpu_timed(magic.inform.forward, pi, tables, threads=1)
    print(f"INFORM forward (physical), batch of {a.forward_n}, 1 thread: {1e6 * t / a.forward_n:.1f}"
          f" us per spectrum (CPU {1e6 * c / a.forward_n:.1f} us)")
    _, t = timed(magic.inform.forward, pi, tables)
    print(f"INFORM forward (physical), batch of {a.forward_n}, all cores: "
          f"{1e6 * t / a.forward_n:.1f} us per spectrum")
    c, t = time.process_time(), time.perf_counter()
    for i in range(a.calls):
        magic.inform.forward(pi[i], tables, threads=1)
    c, t = time.process_time() - c, time.perf_counter() - t
    print(f"INFORM forward, one spectrum per call: {1e6 * t / a.calls:.1f} us per spectrum "
          f"(CPU {1e6 * c / a.calls:.1f} us)")
    pp = prosail_params(a.forward_n, rng)
    _, t, c = cpu_timed(magic.prosail.forward, pp, tables, threads=1)
    print(f"PROSAIL forward (4 factors, 13 bands), batch, 1 thread: "
          f"{1e6 * t / a.forward_n:.1f} us per spectrum (CPU {1e6 * c / a.forward_n:.1f} us)")
    c, t = time.process_time(), time.perf_counter()
    for i in range(a.calls):
        magic.prosail.forward(pp[i], tables, threads=1)
    c, t = time.process_time() - c, time.perf_counter() - t
    print(f"PROSAIL forward, one spectrum per call: {1e6 * t / a.calls:.1f} us per spectrum "
          f"(CPU {1e6 * c / a.calls:.1f} us)")
    try:
        import prosail  # noqa: PLC0415  (optional: the comparison package)
    except ImportError:
        print("prosail package not importable: run_prosail not measured")
        return
    prosail.run_prosail(*pp[0, [0, 1, 2, 4, 5, 6, 7, 8, 9, 10, 11, 12]], ant=pp[0, 3],
                        prospect_version="D", typelidf=2, rsoil=1.0, psoil=pp[0, 13],
                        factor="SDR")  # warm-up (numba compiles on first call)
    c, t = time.process_time(), time.perf_counter()
    for i in range(a.calls):
        q = pp[i]
        prosail.run_prosail(q[0], q[1], q[2], q[4], q[5], q[6], q[7], q[8], q[9], q[10], q[11],
                            q[12], ant=q[3], prospect_version="D", typelidf=2, rsoil=1.0,
                            psoil=q[13], factor="SDR")
    c, t = time.process_time() - c, time.perf_counter() - t
    print(f"prosail {getattr(prosail, '__version__', '')} run_prosail (PROSPECT-D + 4SAIL, 2101 "
          f"wavelengths, no band integration), one spectrum per call: "
          f"{1e6 * t / a.calls:.1f} us per spectrum (CPU {1e6 * c / a.calls:.1f} us)")


if __name__ == "__main__":
    main()
