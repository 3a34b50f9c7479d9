"""Inversion of xarray DataArrays, lazily on Dask when the array is chunked.

``magic.xarray.invert(da, model, dim="band")`` is :meth:`magic.Model.invert` mapped over every
other dimension of ``da`` with :func:`xarray.apply_ufunc` (``dask="parallelized"``): a NumPy-backed
DataArray is inverted at once, a chunked one becomes a Dask graph with one task per chunk that runs
on whatever scheduler is active -- threads, processes, or a ``dask.distributed`` cluster (the model
pickles as its bytes, so every worker gets it with the graph). Inside each task the chunk is
inverted by the Rust core with the GIL released.
"""

from __future__ import annotations

from typing import Any, Hashable, Literal, Optional, Union

import numpy as np
import xarray as xr

from ._magic import Model

__all__ = ["invert"]

#: Units of the result columns that have them (attributes of the returned variables).
UNITS = {
    "x_km": "km",
    "y_km": "km",
    "depth_km": "km",
    "dv_1e6m3": "1e6 m3",
    "cw": "cm",
    "cm": "g cm-2",
    "cab": "ug cm-2",
    "cd": "m",
    "h": "m",
}


#: Units of the result columns named by their unit (GNSS effects' latent variables:
#: ``cm_e_mm``, ``elev_mm_per_km``, ``dv2_1e6m3``, …), by the name's ending.
UNIT_SUFFIXES = (("_mm_per_km", "mm km-1"), ("_1e6m3", "1e6 m3"), ("_mm", "mm"))


def units(column: str) -> str | None:
    """The units of a result column, ``None`` for a dimensionless one (``N``, ``LAI``, …)."""
    if column in UNITS:
        return UNITS[column]
    return next((u for end, u in UNIT_SUFFIXES if column.endswith(end)), None)


def _dtype(column: str) -> np.dtype:
    if column == "flags":
        return np.dtype(np.uint8)
    if column == "stations_used":
        return np.dtype(np.uint32)
    return np.dtype(np.float64)


def _select_inputs(da: xr.DataArray, model: Model, dim: Hashable) -> xr.DataArray:
    """``da`` with its ``dim`` in the model's input order (by label when ``dim`` has string
    labels; by position otherwise)."""
    if dim not in da.dims:
        raise ValueError(f"the DataArray has no dimension {dim!r} (dims {da.dims})")
    inputs = list(model.inputs)
    if dim in da.coords and da[dim].dtype.kind in "USO":
        labels = [str(v) for v in da[dim].values]
        missing = [n for n in inputs if n not in labels]
        if missing:
            raise ValueError(
                f"{dim!r} lacks the model's inputs {missing} (has {labels}); the model reads "
                f"{inputs}"
            )
        return da.sel({dim: inputs})
    if da.sizes[dim] != len(inputs):
        raise ValueError(
            f"{dim!r} has {da.sizes[dim]} entries; the model reads {len(inputs)}: {inputs}"
        )
    return da


def _dates_for(da: xr.DataArray, model: Model, dim: Hashable, dates: Any) -> Optional[Any]:
    if isinstance(dates, str) and dates in da.coords:
        return da.coords[dates]
    if dates is None and model.needs_time:
        times = [
            c for c in da.coords if c != dim and np.issubdtype(da.coords[c].dtype, np.datetime64)
        ]
        if len(times) == 1:
            return da.coords[times[0]]
        raise ValueError(
            "this model needs the observations' dates: pass dates= (a DataArray, or the name "
            "of a datetime64 coordinate of the DataArray)"
        )
    return dates


def _invert_block(obs: np.ndarray, *dates: np.ndarray, model: Model, errors: str,
                  threads: Optional[int]) -> tuple:
    try:
        out = model.invert(obs, dates[0] if dates else None, errors=errors, threads=threads)
    except ValueError as e:
        raise ValueError(f"in a block of shape {obs.shape[:-1]} (index within the block): {e}") \
            from None
    return tuple(out[c] for c in model.outputs)


def invert(
    da: xr.DataArray,
    model: Model,
    dim: Hashable = "band",
    dates: Union[None, str, xr.DataArray, Any] = None,
    *,
    errors: Literal["raise", "nan"] = "raise",
    threads: Optional[int] = None,
) -> xr.Dataset:
    """Inverts every spectrum (or GNSS day) of a DataArray.

    Parameters
    ----------
    da
        Observations in the units ``magic invert`` reads (reflectance, mm), float32 or float64,
        with the channels along ``dim``; NaN marks a missing channel. May be chunked (Dask):
        the chunks along ``dim`` are merged, the others kept, one task per chunk.
    model
        The model (:class:`magic.Model`).
    dim
        The dimension holding the channels. If it has string labels they are matched to
        ``model.inputs`` by name (extra labels are ignored); otherwise its length must equal
        ``len(model.inputs)``, in that order.
    dates
        The dates (see :meth:`magic.Model.invert`): a DataArray broadcastable against ``da``
        without ``dim``, the name of a coordinate of ``da``, or an array shaped like ``da``
        without ``dim``. When omitted and the model needs
        dates, the single datetime64 coordinate of ``da`` is used.
    errors
        ``"raise"``: a pixel that cannot be inverted raises ``ValueError`` when computed (the
        index in the message is within its block); ``"nan"``: NaN in its variables and 0 in
        ``flags`` and ``stations_used``, e.g. for no-data pixels with every band NaN.
    threads
        Threads per block (default: all cores of the worker).

    Returns
    -------
    xarray.Dataset
        One variable per column of ``model.outputs``, with the dimensions and coordinates of
        ``da`` without ``dim`` (lazy when ``da`` is chunked; ``.compute()``, ``.to_zarr()`` or
        ``.to_netcdf()`` run it).
    """
    if not isinstance(da, xr.DataArray):
        raise TypeError(f"da must be an xarray.DataArray, not {type(da).__name__}")
    if not isinstance(model, Model):
        raise TypeError(f"model must be a magic.Model, not {type(model).__name__}")
    if errors not in ("raise", "nan"):
        raise ValueError(f"errors: {errors!r}: expected 'raise' or 'nan'")
    if da.dtype not in (np.float32, np.float64):
        raise TypeError(
            f"da must be float32 or float64 (physical units; NaN for a missing channel), "
            f"not {da.dtype}"
        )
    da = _select_inputs(da, model, dim)
    if da.chunks is not None:
        da = da.chunk({dim: -1})
    args = [da]
    core_dims = [[dim]]
    d = _dates_for(da, model, dim, dates)
    if d is not None:
        if not isinstance(d, xr.DataArray):
            # An array laid out like `da` without `dim`.
            d = xr.DataArray(np.asarray(d), dims=[x for x in da.dims if x != dim])
        if dim in d.dims:
            raise ValueError(f"dates must not have the channel dimension {dim!r}")
        args.append(d)
        core_dims.append([])
    outputs = list(model.outputs)
    results = xr.apply_ufunc(
        _invert_block,
        *args,
        input_core_dims=core_dims,
        output_core_dims=[[] for _ in outputs],
        kwargs={"model": model, "errors": errors, "threads": threads},
        dask="parallelized",
        output_dtypes=[_dtype(c) for c in outputs],
        keep_attrs=False,
    )
    ds = xr.Dataset({c: r for c, r in zip(outputs, results)})
    for c in outputs:
        if (u := units(c)) is not None:
            ds[c].attrs["units"] = u
    ds["flags"].attrs["flag_masks"] = np.array([1, 2, 4], dtype=np.uint8)
    ds["flags"].attrs["flag_meanings"] = "at_bound missing_channels high_residual"
    ds.attrs["magic_problem"] = model.problem
    ds.attrs["magic_variant"] = model.variant
    return ds
