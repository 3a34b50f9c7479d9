"""PROSAIL: PROSPECT-D leaves in one 4SAIL canopy layer over a soil, in Sentinel-2 bands.

The published model as the ``prosail`` package runs it (physical geometry, Campbell's ellipsoidal
leaf angles over 18 bins, soil = ``psoil`` x dry + (1 - ``psoil``) x wet soil spectrum), computed
by the same PROSPECT-D and 4SAIL code as INFORM.
"""

from __future__ import annotations

from typing import Any, Literal, Optional

import numpy as np

from . import _magic
from ._magic import Tables

#: The 14 inputs, in order: ``N, cab, car, anth, cbrown, cw, cm`` (PROSPECT-D), ``lai``, mean
#: leaf angle ``ala`` (degrees), ``hspot``, sun zenith ``tts``, view zenith ``tto``, relative
#: azimuth ``psi`` (degrees), soil brightness ``psoil`` (0-1).
INPUTS = tuple(_magic.PROSAIL_INPUTS)

#: The reflectance factors along axis -2 of the output (4SAIL's meanings): bidirectional,
#: hemispherical-directional, directional-hemispherical, bihemispherical.
FACTORS = tuple(_magic.PROSAIL_FACTORS)


def forward(
    params: Any,
    tables: Tables,
    *,
    errors: Literal["raise", "nan"] = "raise",
    threads: Optional[int] = None,
) -> np.ndarray:
    """The four 4SAIL reflectance factors in the Sentinel-2 bands.

    Parameters
    ----------
    params
        float32/float64 array ``(..., 14)`` in the order of :data:`INPUTS`.
    tables
        The spectral tables (:meth:`magic.Tables.load`).
    errors
        ``"raise"``: a row outside the model's domain raises ``ValueError`` naming its index and
        the input; ``"nan"``: its outputs are NaN.
    threads
        Threads to use (default: all cores).

    Returns
    -------
    numpy.ndarray
        float64 ``(..., 4, 13)``: ``[..., k, b]`` is factor :data:`FACTORS` ``[k]`` in band
        :data:`magic.S2_BANDS` ``[b]``.
    """
    return _magic.prosail_forward(params, tables, errors, threads)
