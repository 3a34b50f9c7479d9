"""INFORM (PROSPECT-D leaves, 4SAIL canopies, FLIM crowns) in the 13 Sentinel-2 bands."""

from __future__ import annotations

from typing import Any, Literal, Optional

import numpy as np

from . import _magic
from ._magic import Tables

#: The 21 inputs, in order (as the columns of ``oracle/rtm_inform_s2_*.csv``): leaf ``N, cab,
#: car, anth, cbrown, cw, cm, cp, cbc``; crown layer ``LAI``, leaf angles ``typeLIDF`` (1 beta
#: table row ``LIDF``, 2 Campbell with mean angle ``LIDF`` in degrees), ``hspot``, ``psoil``;
#: sun zenith ``tts``, view zenith ``tto``, relative azimuth ``psi`` (degrees); understory
#: ``LAIu``; crown diameter ``cd`` (m), stem density ``sd`` (ha^-1), tree height ``h`` (m).
INPUTS = tuple(_magic.INFORM_INPUTS)


def forward(
    params: Any,
    tables: Tables,
    geometry: Literal["physical", "reference"] = "physical",
    *,
    errors: Literal["raise", "nan"] = "raise",
    threads: Optional[int] = None,
) -> np.ndarray:
    """INFORM forest reflectance in the Sentinel-2 bands.

    Parameters
    ----------
    params
        float32/float64 array ``(..., 21)`` in the order of :data:`INPUTS`.
    tables
        The spectral tables (:meth:`magic.Tables.load`).
    geometry
        ``"physical"`` (the published equations) or ``"reference"`` (the paper implementation's
        geometry, which hands INFORM cosines where angles are expected).
    errors
        ``"raise"``: an input row outside the model's domain raises ``ValueError`` naming its
        index and the input; ``"nan"``: its bands are NaN.
    threads
        Threads to use (default: all cores).

    Returns
    -------
    numpy.ndarray
        float64 ``(..., 13)``: reflectance in the bands :data:`magic.S2_BANDS`.
    """
    return _magic.inform_forward(params, tables, geometry, errors, threads)
