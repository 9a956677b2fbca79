"""Two hot paths call SciPy's compiled cores directly, skipping the public wrappers' import or
argument-handling cost: the encoder's tile FFTs (``hcard_builtins.image.fft``, pocketfft) and
the plate loop's filter (``hcard_device.sim.plate.closed_loop``, lfilter's C core). Both keep
the public function as a fallback. Each path, and its fallback, is checked here against an
independent computation, at whatever SciPy version runs the tests (tests/lowest_versions.txt
includes this file, so SciPy 1.10 is covered)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.signal import lfilter

from hcard_builtins.image import fft
from hcard_device.sim import plate


@pytest.fixture(params=["compiled core", "public fallback"])
def tile_fft(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    if request.param == "public fallback":
        monkeypatch.setattr(fft, "_pocketfft", lambda: None)
    else:
        assert fft._pocketfft() is not None, "SciPy's pocketfft was not found"
    return request.param


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize(("tiles", "height", "width"), [(7, 50, 50), (3, 33, 34), (1, 5, 9)])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_tile_fft_matches_numpy(tile_fft, seed, tiles, height, width, dtype) -> None:
    rng = np.random.default_rng(seed)
    batch = rng.normal(size=(tiles, height, width)).astype(dtype)
    spectrum = fft.rfft2(batch)
    expected = np.fft.rfft2(batch.astype(np.float64), axes=(-2, -1))
    tolerance = 1e-4 if dtype == np.float32 else 1e-10
    assert spectrum.shape == expected.shape
    assert spectrum.dtype == (np.complex64 if dtype == np.float32 else np.complex128)
    np.testing.assert_allclose(spectrum, expected, atol=tolerance * np.sqrt(height * width))
    back = fft.irfft2(spectrum, (height, width))
    np.testing.assert_allclose(back, batch, atol=tolerance)


@pytest.fixture(params=["compiled core", "public fallback"])
def loop_filter(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    if request.param == "public fallback":
        monkeypatch.setattr(plate, "_linear_filter", None)
    else:
        assert plate._linear_filter is not None, "lfilter's C core was not found"
    return request.param


def direct_recursion(num, den, x, state):
    """Transposed direct form II of a second-order filter, sample by sample."""
    y = np.empty_like(x)
    z0, z1 = state
    for i, xi in enumerate(x):
        y[i] = num[0] * xi + z0
        z0 = num[1] * xi - den[1] * y[i] + z1
        z1 = num[2] * xi - den[2] * y[i]
    return y, np.array([z0, z1])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_closed_loop_matches_a_direct_recursion_and_lfilter(loop_filter, seed) -> None:
    rng = np.random.default_rng(seed)
    poles = rng.uniform(0.2, 0.95, 2)
    den = np.array([1.0, -(poles[0] + poles[1]), poles[0] * poles[1]])
    num = rng.normal(size=3)
    x = rng.normal(size=300)
    state = rng.normal(size=2)
    y, final = plate.closed_loop(num, den, x, state.copy())
    expected, expected_final = direct_recursion(num, den, x, state)
    np.testing.assert_allclose(y, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(final, expected_final, rtol=1e-12, atol=1e-12)
    public, public_final = lfilter(num, den, x, zi=state)
    np.testing.assert_array_equal(y, public)
    np.testing.assert_array_equal(final, public_final)


@pytest.mark.parametrize("scipy_first", [False, True], ids=["hcard first", "scipy first"])
def test_one_copy_of_pocketfft_per_process(scipy_first: bool) -> None:
    """SciPy 1.10's pybind11 aborts the interpreter at exit ("free(): invalid pointer") once a
    second copy of pocketfft has been initialised: whichever of the encoder and scipy.fft loads
    it first, the other must reuse that copy, and the process must exit cleanly."""
    first, second = "import scipy.fft", "from hcard_builtins.image import fft"
    if not scipy_first:
        first, second = second, first
    script = "\n".join(
        [
            "import sys",
            "import numpy as np",
            first,
            second,
            "tiles = np.arange(2 * 6 * 8, dtype=np.float64).reshape(2, 6, 8)",
            "ours, theirs = fft.rfft2(tiles), scipy.fft.rfft2(tiles)",
            "assert np.allclose(ours, theirs), 'transforms differ'",
            "print(fft._pocketfft() is sys.modules['scipy.fft._pocketfft.pypocketfft'])",
        ]
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"
