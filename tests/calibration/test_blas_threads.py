"""The fits' one-BLAS-thread block: it finds the OpenBLAS libraries NumPy and SciPy loaded, sets
them to one thread and restores them, and the number of threads changes none of the numbers a
fit computes (so the fits give the same answers as with OpenBLAS's default pool)."""

from __future__ import annotations

import sys
import threading

import numpy as np
import pytest
import scipy.linalg

from hcard.calibration import blas_threads
from hcard.calibration.blas_threads import loaded_openblas, one_blas_thread

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
def test_the_thread_count_changes_no_number_of_a_fit(two_threads) -> None:
    """What a trust-region iteration and the covariance compute from a Jacobian of 20,000
    samples x 9 parameters (the size of a calibration fit): SciPy's SVD of the augmented
    Jacobian (C order, as least_squares builds it), NumPy's SVD and the products J^T f and
    J p, bit for bit with two threads and with one."""
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(20_009, 9)) * np.logspace(0, -6, 9)
    f = rng.normal(size=20_009)
    p = rng.normal(size=9)

    def numbers() -> list[np.ndarray]:
        u, s, vt = scipy.linalg.svd(jac, full_matrices=False)
        _, s2, vt2 = np.linalg.svd(jac, full_matrices=False)
        return [u.T.dot(f), s, vt, s2, vt2, jac.T.dot(f), jac.dot(p)]

    pooled = numbers()
    with one_blas_thread():
        single = numbers()
    for a, b in zip(pooled, single, strict=True):
        np.testing.assert_array_equal(a, b)
