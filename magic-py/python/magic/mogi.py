"""The Mogi point source under a GNSS network (elastic half-space, Poisson ratio 0.25)."""

from __future__ import annotations

import json
import os
from typing import Any, Literal, Mapping, Optional, Union

import numpy as np

from . import _magic

#: The source parameters, in order: east and north of the network origin (km), depth below it
#: (km), volume change (10^6 m^3).
PARAMS = tuple(_magic.MOGI_PARAMS)

Stations = Union[str, "os.PathLike[str]", Mapping[str, Mapping[str, float]], np.ndarray]


def station_positions(stations: Stations) -> np.ndarray:
    """Station positions as a float64 ``(n_stations, 3)`` array (east, north, elevation; km).

    ``stations`` is a ``stations.json`` file (``{"STA": {"xE": km, "yN": km, "zV": km}, ...}``,
    stations in file order), the mapping such a file holds, or an ``(n_stations, 3)`` array.
    """
    if isinstance(stations, (str, os.PathLike)):
        with open(stations, encoding="utf-8") as f:
            try:
                stations = json.load(f)
            except json.JSONDecodeError as e:
                raise ValueError(f"{os.fspath(stations)}: {e}") from None
    if isinstance(stations, Mapping):
        rows = []
        for name, s in stations.items():
            try:
                rows.append([float(s["xE"]), float(s["yN"]), float(s["zV"])])
            except (KeyError, TypeError, ValueError) as e:
                raise ValueError(f"station {name}: needs numbers xE, yN, zV ({e!r})") from None
        stations = rows
    a = np.asarray(stations)
    if a.dtype.kind not in "iuf":
        raise TypeError(f"stations must hold numbers, not {a.dtype}")
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] == 0:
        raise ValueError(f"stations: shape {a.shape}; expected (n_stations, 3)")
    return np.ascontiguousarray(a, dtype=np.float64)


def forward(
    params: Any,
    stations: Stations,
    *,
    errors: Literal["raise", "nan"] = "raise",
    threads: Optional[int] = None,
) -> np.ndarray:
    """Surface displacements of Mogi sources at the stations.

    Parameters
    ----------
    params
        float32/float64 array ``(..., 4)``: ``x_km, y_km, depth_km, dv_1e6m3`` per source.
    stations
        ``stations.json`` path, its mapping, or an ``(n_stations, 3)`` array (see
        :func:`station_positions`).
    errors
        ``"raise"``: a source that cannot be evaluated (non-finite parameter, depth <= 0) raises
        ``ValueError`` naming its index; ``"nan"``: its displacements are NaN.
    threads
        Threads to use (default: all cores).

    Returns
    -------
    numpy.ndarray
        float64 ``(..., 3 * n_stations)`` in mm: east for every station, then north, then up (the
        channel order ``ux_<STA>``, ``uy_<STA>``, ``uz_<STA>`` of the data).
    """
    return _magic.mogi_forward(params, station_positions(stations), errors, threads)
