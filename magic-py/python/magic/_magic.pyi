"""Type stubs of the native module `magic._magic` (Rust, PyO3)."""

import os
import pathlib
from typing import Any, Dict, List, Literal, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

_Floats = npt.ArrayLike
_Path = Union[str, "os.PathLike[str]"]
_Errors = Literal["raise", "nan"]

__version__: str
S2_BANDS: List[str]
INFORM_INPUTS: List[str]
PROSAIL_INPUTS: List[str]
PROSAIL_FACTORS: List[str]
MOGI_PARAMS: List[str]

class Model:
    """A trained model file (`magic train` / `magic export`): observations to physical
    variables."""

    def __new__(cls, data: bytes) -> "Model": ...
    @staticmethod
    def load(path: _Path) -> "Model":
        """Reads a model file (`OSError` if unreadable, `ValueError` if not a valid model)."""
    @staticmethod
    def from_bytes(data: bytes) -> "Model":
        """Decodes and validates model bytes (`ValueError` if corrupt, truncated or foreign)."""
    def to_bytes(self) -> bytes:
        """The model file's bytes."""
    @property
    def problem(self) -> Literal["mogi", "rtm"]:
        """`"mogi"` (volcano source under a GNSS network) or `"rtm"` (forest spectra)."""
    @property
    def variant(self) -> Literal["A", "B", "C"]:
        """The paper's variant."""
    @property
    def inputs(self) -> List[str]:
        """Input channels in order (the last axis of `obs`)."""
    @property
    def outputs(self) -> List[str]:
        """Result columns as `magic invert` writes them."""
    @property
    def bounds(self) -> Dict[str, Tuple[float, float]]:
        """The variables' bounds `{name: (min, max)}` (empty for variant A)."""
    @property
    def needs_time(self) -> bool:
        """Whether inversions need the observations' dates."""
    def invert(
        self,
        obs: _Floats,
        dates: Optional[Any] = None,
        *,
        errors: _Errors = "raise",
        threads: Optional[int] = None,
        sd: bool = False,
    ) -> Dict[str, np.ndarray]:
        """Inverts observations `(..., len(inputs))` (float32/float64, NaN missing): one array
        per column of `outputs`, shaped `obs.shape[:-1]`; with `sd=True` also `<variable>_sd`
        per variable (as `magic invert --sd`)."""
    def __reduce__(self) -> Tuple[Any, Tuple[bytes]]: ...

class Tables:
    """The spectral tables INFORM and PROSAIL run on (the `rtm/` folder of the data)."""

    @staticmethod
    def load(dir: _Path) -> "Tables":
        """Reads the tables (`OSError` for a missing file, `ValueError` for a malformed one)."""
    @property
    def dir(self) -> "pathlib.Path":
        """The folder the tables were read from."""
    def __len__(self) -> int: ...
    @staticmethod
    def _from_parts(dir: _Path, parts: List[bytes]) -> "Tables": ...
    def __reduce__(self) -> Tuple[Any, Tuple[Any, ...]]: ...

def mogi_forward(
    params: _Floats,
    stations: npt.NDArray[np.float64],
    errors: _Errors = "raise",
    threads: Optional[int] = None,
) -> npt.NDArray[np.float64]: ...
def inform_forward(
    params: _Floats,
    tables: Tables,
    geometry: Literal["physical", "reference"] = "physical",
    errors: _Errors = "raise",
    threads: Optional[int] = None,
) -> npt.NDArray[np.float64]: ...
def prosail_forward(
    params: _Floats,
    tables: Tables,
    errors: _Errors = "raise",
    threads: Optional[int] = None,
) -> npt.NDArray[np.float64]: ...
