"""magic: learned inversion of physical models with bias correction.

Observations X (daily GNSS displacements of a volcano network; Sentinel-2 forest spectra) go
through an encoder to physical variables Z (a Mogi magma source; leaf and canopy variables of
INFORM), the physical forward model rebuilds X, and a small correction absorbs systematic bias.
This package runs trained model files and the forward models from NumPy, xarray and Dask; the
numbers are those of the ``magic`` command line (the same Rust core, in float64, on every core,
with the GIL released).

* :class:`Model` -- a model file: ``Model.load(path)``, ``model.invert(obs, dates=None)``;
* :class:`Tables` -- the spectral tables INFORM and PROSAIL run on: ``Tables.load(dir)``;
* :mod:`magic.mogi`, :mod:`magic.inform`, :mod:`magic.prosail` -- the forward models;
* :mod:`magic.xarray` -- ``magic.xarray.invert(da, model)`` on (chunked) DataArrays, on any Dask
  scheduler, a ``distributed`` cluster included.

Errors are Python exceptions carrying the core's message: ``TypeError`` for input of the wrong
kind, ``ValueError`` for wrong shapes, values the model cannot take and corrupt model bytes,
``OSError`` for files that cannot be read.
"""

from ._magic import S2_BANDS, Model, Tables, __version__
from . import inform, mogi, prosail

__all__ = ["Model", "Tables", "S2_BANDS", "__version__", "mogi", "inform", "prosail"]
