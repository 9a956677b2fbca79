"""The fits' one-BLAS-thread block: it finds the OpenBLAS libraries NumPy and SciPy loaded, sets
them to one thread and restores them. The SVDs of a fit's Jacobian are the same bits on one
thread and on two; long sums (the cost) may differ in their last bit, and a fit on OpenBLAS's
pool then ends within its convergence tolerance of the fit on one thread, on a recording
generated independently of the library (independent_recordings.py)."""

from __future__ import annotations

import math
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from hcard.calibration import blas_threads
from hcard.calibration.blas_threads import loaded_openblas, one_blas_thread
from hcard.calibration.effects import augment
from hcard.calibration.fit import fit_predictor
from hcard.calibration.observation import lateral_force_model
from hcard.plugins.registry import get_registry

sys.path.insert(0, str(Path(__file__).resolve().parent))
import independent_recordings as ir

POOL_DEVIATION = 1e-3
"""Largest change of a fitted value, in units of its uncertainty, between a fit on OpenBLAS's
pool and on one thread that these tests allow (measured: 9.3e-7; a fit's convergence tolerance,
a cost that falls by less than 1e-8 of itself per iteration, leaves ~1e-2 on 12,000 samples)."""

linux_wheels = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="the libraries are found in /proc/self/maps"
)


def counts() -> list[int]:
    return [int(lib.get_threads()) for lib in loaded_openblas()]


@pytest.fixture
def two_threads():
    """Every loaded OpenBLAS on two threads during the test, its own count restored after."""
    libraries = loaded_openblas()
    before = counts()
    for lib in libraries:
        lib.set_threads(2)
    yield libraries
    for lib, threads in zip(libraries, before, strict=True):
        lib.set_threads(threads)


@linux_wheels
def test_numpy_and_scipy_openblas_are_found() -> None:
    paths = [lib.path for lib in loaded_openblas()]
    numpy_dir = np.__file__.rsplit("/", 2)[0]  # site-packages: numpy.libs/ beside numpy/
    assert any(path.startswith(numpy_dir) and "numpy" in path for path in paths), paths
    assert any("scipy" in path for path in paths), paths


@linux_wheels
def test_one_thread_inside_and_the_counts_restored_after(two_threads) -> None:
    assert counts() == [2, 2]  # NumPy's and SciPy's
    with one_blas_thread():
        assert counts() == [1, 1]
        with one_blas_thread():  # nested: the inner exit restores nothing
            pass
        assert counts() == [1, 1]
    assert counts() == [2, 2]
    with pytest.raises(RuntimeError), one_blas_thread():  # restored on an error too
        raise RuntimeError("inside")
    assert counts() == [2, 2]


@linux_wheels
def test_threads_overlapping_blocks_restore_once_the_last_leaves(two_threads) -> None:
    inside, leave = threading.Event(), threading.Event()

    def other() -> None:
        with one_blas_thread():
            inside.set()
            leave.wait(5.0)

    worker = threading.Thread(target=other)
    worker.start()
    try:
        assert inside.wait(5.0)
        with one_blas_thread():
            pass
        assert counts() == [1, 1]  # the other thread's block still runs
    finally:
        leave.set()
        worker.join()
    assert counts() == [2, 2]


def test_without_a_memory_map_nothing_is_changed(monkeypatch, tmp_path) -> None:
    monkeypatch.setattr(blas_threads, "MEMORY_MAP", tmp_path / "missing")
    assert loaded_openblas() == []
    with one_blas_thread():
        pass


@linux_wheels
def test_the_thread_count_changes_no_svd_of_a_jacobian(two_threads) -> None:
    """The SVDs of a fit's Jacobian, 20,000 samples x 9 parameters: SciPy's of the augmented
    Jacobian (C order, as least_squares builds it) in its trust-region step and NumPy's in the
    covariance, bit for bit with two threads and with one."""
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(20_009, 9)) * np.logspace(0, -6, 9)

    def numbers() -> list[np.ndarray]:
        return [*scipy.linalg.svd(jac, full_matrices=False),
                *np.linalg.svd(jac, full_matrices=False)]

    pooled = numbers()
    with one_blas_thread():
        single = numbers()
    for a, b in zip(pooled, single, strict=True):
        np.testing.assert_array_equal(a, b)


@linux_wheels
def test_a_fit_on_the_pool_ends_within_its_tolerance_of_the_fit_on_one_thread(
    two_threads, monkeypatch
) -> None:
    """A recording with charge leakage hidden, fitted with an air layer and the finger's
    geometry (two effects that both scale the electrostatic force with the load: a weakly
    determined direction, where a last-bit change of the cost moves the end point most). On
    this recording the two fits differ (by up to 9.3e-7 of the uncertainty, in ``area``)."""
    seed = 3
    registry = get_registry()
    data = ir.calibration_data(ir.Scenario("ev", ("charge-leakage",)), seed)
    effects = [registry.calibration_effects[name] for name in ("air-layer", "finger-geometry")]
    model = lateral_force_model(augment(registry.get("predictor", "ev-kaczmarek"), effects))
    free = ["area", "air-layer.air_gap", "finger-geometry.area_index", "force_offset"]
    assert set(free) <= {p.name for p in model.parameters}
    inputs = data.inputs_for(model)

    def fit():
        return fit_predictor(model, inputs, data.observed, free=free, train=data.train,
                             test=data.test)

    single = fit()
    assert counts() == [2, 2]
    monkeypatch.setattr(blas_threads, "loaded_openblas", lambda: [])  # the pool stays on
    pooled = fit()
    assert single.n_train > 10_000  # long enough for OpenBLAS to split its sums
    for name in free:
        sigma = pooled.uncertainties[name]
        assert math.isfinite(sigma) and sigma > 0
        assert abs(single.params[name] - pooled.params[name]) <= POOL_DEVIATION * sigma, name
        assert single.uncertainties[name] == pytest.approx(sigma, rel=POOL_DEVIATION)
    assert single.test_rmse == pytest.approx(pooled.test_rmse, rel=1e-9)
