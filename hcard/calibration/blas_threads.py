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
tests/calibration/independent_recordings.py and 2 of the simulated coupled stimulator, the
final fits, their uncertainties and the bootstrap's refits and intervals were the same bits;
candidate fits moved their held-out RMSE by up to 4.7e-7 of itself and a weakly determined fit
its values by up to 9.3e-7 of their uncertainty (tests/calibration/test_blas_threads.py bounds
that at 1e-3).

:func:`one_blas_thread` sets every OpenBLAS library loaded in the process (NumPy's and SciPy's
wheels each bring their own) to one thread and restores the counts when the outermost use
ends. The libraries are found in the process's memory map (Linux); where there is none, or
the BLAS is not OpenBLAS, it changes nothing.
"""

from __future__ import annotations

import ctypes
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

MEMORY_MAP = Path("/proc/self/maps")
"""The libraries this process has loaded, one mapping a line (Linux)."""

SYMBOLS = (
    # (getter, setter): SciPy's and NumPy's wheels since 2024 (64-bit and 32-bit integers),
    # then older wheels and system builds
    ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
    ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
    ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
    ("openblas_get_num_threads", "openblas_set_num_threads"),
)
"""Names of OpenBLAS's thread-count functions, in the order they are looked for."""


@dataclass(frozen=True)
class BlasLibrary:
    """A loaded OpenBLAS library and its thread-count functions.

    Attributes:
        path: the shared library's file.
        get_threads: returns the number of threads its calls use.
        set_threads: sets that number (from the next call on).
    """

    path: str
    get_threads: ctypes._CFuncPtr  # type: ignore[name-defined]
    set_threads: ctypes._CFuncPtr  # type: ignore[name-defined]


def loaded_openblas() -> list[BlasLibrary]:
    """The OpenBLAS libraries this process has loaded (none where there is no memory map)."""
    try:
        text = MEMORY_MAP.read_text()
    except OSError:
        return []
    paths = sorted({
        fields[5]
        for fields in (line.split(maxsplit=5) for line in text.splitlines()
                       if "openblas" in line.lower())
        if len(fields) == 6
    })
    found = []
    for path in paths:
        try:
            library = ctypes.CDLL(path)  # already loaded: the same handle, nothing runs
        except OSError:
            continue
        for getter, setter in SYMBOLS:
            get = getattr(library, getter, None)
            put = getattr(library, setter, None)
            if get is not None and put is not None:
                get.restype, get.argtypes = ctypes.c_int, []
                put.restype, put.argtypes = None, [ctypes.c_int]
                found.append(BlasLibrary(path, get, put))
                break
    return found


_lock = threading.Lock()
_depth = 0
_saved: list[tuple[BlasLibrary, int]] = []


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with every loaded OpenBLAS on one thread (module docstring).

    Nests (only the outermost use sets and restores) and is safe to enter from several
    threads at once; the thread count is the process's, so other threads' BLAS calls run on
    one thread too while any block runs.
    """
    global _depth
    with _lock:
        if _depth == 0:
            _saved[:] = [(lib, int(lib.get_threads())) for lib in loaded_openblas()]
            for lib, threads in _saved:
                if threads != 1:
                    lib.set_threads(1)
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                for lib, threads in _saved:
                    if threads != 1:
                        lib.set_threads(threads)
                _saved.clear()
