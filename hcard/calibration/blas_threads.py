"""One BLAS thread while the calibration fits.

A fit's linear algebra is on tall, narrow matrices: the trust-region step of
:func:`scipy.optimize.least_squares` takes the SVD of the Jacobian (tens of thousands of
training samples by at most a dozen parameters) and forms ``J^T f`` every iteration, between
model evaluations that are NumPy element-wise code on one core. OpenBLAS's thread pool gains
nothing on a matrix a dozen columns wide, and its threads, spinning for work after each call,
take the cores the model evaluations need; on a busy machine every call also waits for its
second thread to be scheduled. On 2 cores one thread made the calibration loop and the 50
refits of a stroke bootstrap of a 30 s recording 1.9-2.3x faster with the machine otherwise
idle, and 6-12x at a load average of 2-3 from other processes (bench/bench_bootstrap.py).

The number of threads changes the last bits of long sums only: OpenBLAS splits a dot product
over more than about 10,000 samples (the cost ``f^T f``), and a product of a long matrix with a
vector, into one part per thread, so the pool's rounding depended on the machine's number of
cores; the SVDs of a fit's Jacobian come out the same bits on one thread and on two
(tests/calibration/test_blas_threads.py). A cost that differs in its last bit can end a fit one
iteration earlier or later, inside its convergence tolerance; on one thread the fits no longer
depend on the core count. Against the pool on 2 cores, on 10 recordings of
tests/helpers/independent_recordings.py and 2 of the simulated coupled stimulator, the
final fits, their uncertainties and the bootstrap's refits and intervals were the same bits;
candidate fits moved their held-out RMSE by up to 4.7e-7 of itself and a weakly determined fit
its values by up to 9.3e-7 of their uncertainty (tests/calibration/test_blas_threads.py bounds
that at 1e-3).

The BLAS libraries are found and set by :mod:`threadpoolctl` (every BLAS the process has
loaded: NumPy's and SciPy's wheels each bring their own OpenBLAS). Blocks nest, and the counts
found are restored when the outermost block ends. OpenBLAS's pool is process-wide: a block in
one Python thread sets it for all threads.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from threadpoolctl import threadpool_limits

P = ParamSpec("P")
R = TypeVar("R")


def one_blas_thread() -> threadpool_limits:
    """A context manager that runs its block with every loaded BLAS on one thread and restores
    the thread counts after (module docstring)."""
    return threadpool_limits(limits=1, user_api="blas")


def on_one_blas_thread(function: Callable[P, R]) -> Callable[P, R]:
    """Decorator: every call of ``function`` runs in :func:`one_blas_thread`."""

    @functools.wraps(function)
    def on_one_thread(*args: P.args, **kwargs: P.kwargs) -> R:
        with one_blas_thread():
            return function(*args, **kwargs)

    return on_one_thread
