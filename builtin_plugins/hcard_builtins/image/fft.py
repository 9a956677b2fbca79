"""Real 2-D FFTs of batches of small tiles, without the import cost of :mod:`scipy.fft`.

Transforms run on one thread: on a shared 2-core machine a second FFT thread waited for a core
as often as it helped (500-1700 tiles of 50 x 50: 0.6-1.6x the single-thread time), and one
thread keeps the encoder's time predictable.

The encoder transforms thousands of tiles of a few dozen pixels. scipy's compiled pocketfft
does such a batch about four times faster than :func:`numpy.fft.rfft2` (which pays a per-row
overhead), but ``import scipy.fft`` costs 0.2-0.4 s: it imports :mod:`scipy.special` and scipy's
array-API layer, which imports ``numpy.testing``, ``numpy.f2py`` and more; that is more than
a whole encode of a 1024 x 1024 image. The compiled module (``pypocketfft``, the code
:func:`scipy.fft.rfft2` itself calls) is a stand-alone extension, so it is loaded here from
scipy's installation on its own. Should that ever fail (a scipy that moved or renamed it), the
public :func:`scipy.fft.rfft2` and :func:`scipy.fft.irfft2` are used instead: the same numbers,
only a slower start.

The extension must be initialised once per process: older pybind11 builds (SciPy 1.10) abort at
interpreter exit ("free(): invalid pointer") when a second copy of the module is created. So
the module scipy already imported is reused, and the one loaded here is registered under
scipy's own name, where a later ``import scipy.fft`` finds it instead of loading another.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
from collections.abc import Callable
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

_SCIPY_NAME = "scipy.fft._pocketfft.pypocketfft"


@cache
def _pocketfft() -> ModuleType | None:
    """scipy's compiled pocketfft module, loaded without importing :mod:`scipy.fft`, or None."""
    loaded = sys.modules.get(_SCIPY_NAME)
    if loaded is not None:
        return loaded if _has_transforms(loaded) else None
    try:
        spec = importlib.util.find_spec("scipy")
        if spec is None or spec.origin is None:
            return None
        folder = Path(spec.origin).parent / "fft" / "_pocketfft"
        suffixes = tuple(importlib.machinery.EXTENSION_SUFFIXES)
        files = sorted(p for p in folder.glob("pypocketfft*") if p.name.endswith(suffixes))
        if not files:
            return None
        name = "pypocketfft"  # must match the module's init function
        loader = importlib.machinery.ExtensionFileLoader(name, str(files[0]))
        module_spec = importlib.util.spec_from_file_location(name, files[0], loader=loader)
        if module_spec is None:
            return None
        module = importlib.util.module_from_spec(module_spec)
        loader.exec_module(module)
    except (ImportError, OSError):
        return None
    sys.modules[_SCIPY_NAME] = module  # scipy.fft's own import then reuses this one copy
    return module if _has_transforms(module) else None


def _has_transforms(module: ModuleType) -> bool:
    return callable(getattr(module, "r2c", None)) and callable(getattr(module, "c2r", None))


def _scipy(name: str) -> Callable[..., Any]:
    import scipy.fft  # the slow import, only when the compiled module is not available

    return getattr(scipy.fft, name)


def rfft2(tiles: np.ndarray) -> np.ndarray:
    """Unnormalised real FFT over the last two axes of ``tiles`` ``(n, nh, nw)``: complex array
    ``(n, nh, nw // 2 + 1)``, single precision for ``float32`` input (as
    :func:`scipy.fft.rfft2`)."""
    module = _pocketfft()
    if module is None:
        return _scipy("rfft2")(tiles, axes=(-2, -1))
    return module.r2c(tiles, (tiles.ndim - 2, tiles.ndim - 1), True, 0, None, 1)


def irfft2(spectrum: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Inverse of :func:`rfft2` for tiles of ``shape`` ``(nh, nw)`` (normalised by ``1/(nh nw)``,
    as :func:`scipy.fft.irfft2`)."""
    module = _pocketfft()
    if module is None:
        return _scipy("irfft2")(spectrum, s=shape, axes=(-2, -1))
    nw = shape[1]
    axes = (spectrum.ndim - 2, spectrum.ndim - 1)
    # c2r transforms the first axes as complex-to-complex and the last one complex-to-real;
    # ``lastsize`` is the length of the real output along that axis.
    return module.c2r(spectrum, axes, nw, False, 2, None, 1)
