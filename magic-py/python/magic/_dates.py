"""Dates to day numbers (days since 1970-01-01, float64, NaN unknown), as the core reads them."""

from __future__ import annotations

from typing import Any, Tuple

import numpy as np


def day_numbers(dates: Any, shape: Tuple[int, ...]) -> np.ndarray:
    """``dates`` (datetime64, ISO strings ``YYYY-MM-DD`` / ``YYYY.MM.DD``, or numbers of days
    since 1970-01-01) as a C-contiguous float64 array of ``shape`` (broadcast); NaT, NaN and
    empty strings become NaN. Other values raise ``TypeError`` or ``ValueError``."""
    d = np.asarray(dates)
    if d.dtype.kind in "US":
        text = np.char.replace(d.astype(str), ".", "-")
        empty = np.char.str_len(text) == 0
        try:
            d = np.where(empty, "NaT", text).astype("datetime64[D]")
        except ValueError as e:
            raise ValueError(f"dates: {e} (expected YYYY-MM-DD or YYYY.MM.DD)") from None
    elif d.dtype.kind == "O":
        try:
            d = d.astype("datetime64[D]")
        except (TypeError, ValueError) as e:
            raise TypeError(f"dates: {e}") from None
    if d.dtype.kind == "M":
        days = d.astype("datetime64[D]")
        out = days.astype(np.int64).astype(np.float64)
        out[np.isnat(days)] = np.nan
    elif d.dtype.kind in "iuf":
        out = d.astype(np.float64)
    else:
        raise TypeError(
            f"dates must be datetime64, date strings or day numbers, not {d.dtype}"
        )
    try:
        out = np.broadcast_to(out, shape)
    except ValueError:
        raise ValueError(
            f"dates: shape {d.shape} does not broadcast to obs.shape[:-1] = {tuple(shape)}"
        ) from None
    return np.ascontiguousarray(out, dtype=np.float64)
