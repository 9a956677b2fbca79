"""The fits' one-BLAS-thread block: it sets the BLAS libraries NumPy and SciPy loaded to one
thread and restores them (through threadpoolctl), once for nested blocks and blocks of several
threads. The SVDs of a fit's Jacobian are the same bits on one thread and on two; long sums (the
cost) may differ in their last bit, and a fit on OpenBLAS's pool then ends within its
convergence tolerance of the fit on one thread, on a recording generated independently of the
library (independent_recordings.py)."""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Iterator

import numpy as np
import pytest
import scipy.linalg
from threadpoolctl import threadpool_info, threadpool_limits

from hcard.calibration import blas_threads
from hcard.calibration.blas_threads import one_blas_thread
from hcard.calibration.fit import fit_predictor
from hcard.calibration.observation import lateral_force_model
from hcard.physics.effects import augment
from hcard.plugins.registry import get_registry
from tests.helpers import independent_recordings as ir

POOL_DEVIATION = 1e-3
"""Largest change of a fitted value, in units of its uncertainty, between a fit on OpenBLAS's
pool and on one thread that these tests allow (measured: 9.3e-7; a fit's convergence tolerance,
a cost that falls by less than 1e-8 of itself per iteration, leaves ~1e-2 on 12,000 samples)."""


SVD_MAX_ULP = 2
"""Largest difference, in units in the last place, between an SVD on one BLAS thread and on two
(seen: 1, at one element of 180,081, with NumPy 2.4.6 and SciPy 1.17.1)."""


def counts() -> list[int]:
    """Threads of each loaded BLAS, NumPy's and SciPy's (in threadpoolctl's order)."""
    return [int(info["num_threads"]) for info in threadpool_info()
            if info["user_api"] == "blas"]


@pytest.fixture
def two_threads():
    """Every loaded BLAS on two threads during the test, its own count restored after."""
    with threadpool_limits(limits=2, user_api="blas"):
        yield


def test_numpy_and_scipy_blas_are_both_set() -> None:
    paths = [info["filepath"] for info in threadpool_info() if info["user_api"] == "blas"]
    assert any("numpy" in path for path in paths), paths
    assert any("scipy" in path for path in paths), paths


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


def test_a_block_in_another_thread_sets_one_thread_and_restores_the_counts() -> None:
    before = counts()
    inside, leave = threading.Event(), threading.Event()
    seen: list[list[int]] = []

    def other() -> None:
        with one_blas_thread():
            seen.append(counts())
            inside.set()
            leave.wait(5.0)

    worker = threading.Thread(target=other)
    worker.start()
    try:
        assert inside.wait(5.0)
        assert counts() == [1, 1]  # process-wide while the other thread's block runs
    finally:
        leave.set()
        worker.join()
    assert seen == [[1, 1]]
    assert counts() == before


def test_the_decorator_runs_each_call_on_one_thread(two_threads) -> None:
    @blas_threads.on_one_blas_thread
    def threads_inside(offset: int) -> list[int]:
        return [n + offset for n in counts()]

    assert threads_inside(10) == [11, 11]
    assert counts() == [2, 2]


def test_the_thread_count_changes_no_svd_of_a_jacobian(two_threads) -> None:
    """The SVDs of a fit's Jacobian, 20,000 samples x 9 parameters: SciPy's of the augmented
    Jacobian (C order, as least_squares builds it) in its trust-region step and NumPy's in the
    covariance, equal with two threads and with one to :data:`SVD_MAX_ULP` units in the last
    place (OpenBLAS promises no bit-identity across thread counts: on NumPy 2.4.6's build one
    element in 180,081 differs by one unit, at the row where the two threads' halves meet)."""
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(20_009, 9)) * np.logspace(0, -6, 9)

    def numbers() -> list[np.ndarray]:
        return [*scipy.linalg.svd(jac, full_matrices=False),
                *np.linalg.svd(jac, full_matrices=False)]

    pooled = numbers()
    with one_blas_thread():
        single = numbers()
    for a, b in zip(pooled, single, strict=True):
        np.testing.assert_array_max_ulp(a, b, maxulp=SVD_MAX_ULP)


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
    seen: list[list[int]] = []  # counts() on entering and leaving each block the fit opened

    @contextlib.contextmanager
    def the_pool_stays_on(**_: object) -> Iterator[None]:
        with threadpool_limits(limits=None):
            seen.append(counts())
            yield
            seen.append(counts())

    monkeypatch.setattr(blas_threads, "threadpool_limits", the_pool_stays_on)
    pooled = fit()
    assert seen and all(c == [2, 2] for c in seen), seen  # else both fits ran on one thread
    assert single.n_train > 10_000  # long enough for OpenBLAS to split its sums
    for name in free:
        sigma = pooled.uncertainties[name]
        assert math.isfinite(sigma) and sigma > 0
        assert abs(single.params[name] - pooled.params[name]) <= POOL_DEVIATION * sigma, name
        assert single.uncertainties[name] == pytest.approx(sigma, rel=POOL_DEVIATION)
    assert single.test_rmse == pytest.approx(pooled.test_rmse, rel=1e-9)
