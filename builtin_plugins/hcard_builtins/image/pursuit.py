"""Residual pursuit: gratings added to a taxtel until its error meets the target.

The spectral analysis (:mod:`.spectral`) finds gratings: components with an accurate frequency,
which neighbouring taxtels share. What it leaves (edges, shapes, detail that is not a grating)
stays in the residual ``image - texture`` of the taxtel. This module adds components that
remove the largest part of that residual:

- the residual of a tile (``nh x nw`` pixels, zero on pixels the taxtel does not own) is
  expanded in the tile's own harmonics, its unwindowed 2-D DFT ``X``. Harmonic ``(ky, kx)`` and
  its mirror image ``(-ky, -kx)`` together are one grating of ``kx`` cycles per tile width and
  ``ky`` per tile height with complex amplitude ``c = X / (nh nw)`` (the convention of
  :class:`.spectral.TileSpectra`);
- the harmonics are orthogonal over the tile, so removing grating ``b`` lowers the residual's
  sum of squares by exactly ``2 |X_b|^2 / (nh nw)`` (Parseval): the best ``j`` gratings are the
  ``j`` largest, and the error left after them is known without rendering;
- each tile takes the fewest gratings whose remaining RMS meets the goal (at most its free
  slots), then the 95th percentile of what is left is checked on the pixels
  (:func:`.fft.irfft2`): a tile still over the target takes more, up to its free slots.

Frequencies here are integers (cycles per tile); :func:`.spectral.to_surface` turns them into
cycles/mm and surface phases like any other component.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fft import irfft2, rfft2
from .reconstruct import counts_present, percentile_rank
from .spectral import TileSpectra

_GROWTH_ROUNDS = 4
"""Times a tile still over the target after its first choice takes more gratings."""


@dataclass(frozen=True)
class Pursuit:
    """Result of :func:`pursue` for ``n`` tiles.

    Attributes:
        spectra: the added gratings (``fx``, ``fy`` integers, cycles per tile), ``(n, m)``;
            ``mean`` is the residual's mean over the tile, which the baseline takes.
        count: ``(n,)`` gratings added to each tile.
        p95: ``(n,)`` 95th percentile of the absolute residual left on the owned pixels, gray
            levels (with the added gratings, before the palette).
        rms_at_limit: ``(n,)`` RMS residual per owned pixel that ``limit`` gratings would leave
            (the most a texture can hold minus those the tile already has), gray levels.
    """

    spectra: TileSpectra
    count: np.ndarray
    p95: np.ndarray
    rms_at_limit: np.ndarray


def candidate_bins(nh: int, nw: int, allowed: np.ndarray | None = None) -> np.ndarray:
    """``(nh, nw // 2 + 1)`` mask of the rfft bins that can become gratings: one bin of each
    mirror pair (``X(-k) = conj X(k)``), neither DC nor a bin that is its own mirror image (a
    Nyquist grating has no phase of its own), and, if given, only where ``allowed`` is True."""
    mask = np.ones((nh, nw // 2 + 1), dtype=bool)
    columns = [0] + ([nw // 2] if nw % 2 == 0 else [])
    for col in columns:  # pairs inside these columns: keep the upper half
        mask[nh // 2 + 1 :, col] = False
        mask[0, col] = False
        if nh % 2 == 0:
            mask[nh // 2, col] = False
    if allowed is not None:
        mask &= allowed
    return mask


def pursue(
    residual: np.ndarray,
    *,
    mask: np.ndarray,
    free: np.ndarray,
    limit: np.ndarray,
    goal_rms: float,
    target: float,
    allowed: np.ndarray | None = None,
) -> Pursuit:
    """Gratings that bring each tile's residual under the target.

    Args:
        residual: ``(n, nh, nw)`` image minus the taxtel's texture, gray levels, zero on the
            pixels the taxtel does not own.
        mask: ``(n, nh, nw)`` 1 on the pixels each taxtel owns, 0 elsewhere (float32).
        free: ``(n,)`` gratings each tile may take.
        limit: ``(n,)`` gratings each tile could take at the format's limit (>= ``free``), for
            :attr:`Pursuit.rms_at_limit`.
        goal_rms: RMS residual per owned pixel aimed at when choosing, gray levels.
        target: the 95th percentile of the absolute residual must not exceed this, gray levels.
        allowed: ``(nh, nw // 2 + 1)`` bins that may be used (e.g. the frequency limit).
    """
    n, nh, nw = residual.shape
    pixels = nh * nw
    owned = np.rint(mask.reshape(n, -1).sum(axis=1)).astype(np.int64)
    width = int(limit.max(initial=0))
    spectra = TileSpectra.empty(n, width)
    zeros = np.zeros(n, dtype=np.int64)
    if n == 0 or width == 0:
        rms, p95 = error_figures(residual, mask)
        return Pursuit(spectra, zeros, p95, rms)
    spectrum = rfft2(residual)
    power = spectrum.real**2 + spectrum.imag**2
    power *= candidate_bins(nh, nw, allowed)
    flat = power.reshape(n, -1)
    top = np.argpartition(-flat, width - 1, axis=1)[:, :width]
    order = np.argsort(-np.take_along_axis(flat, top, axis=1), axis=1, kind="stable")
    top = np.take_along_axis(top, order, axis=1)  # (n, width) strongest first
    removed = np.cumsum(2.0 * np.take_along_axis(flat, top, axis=1).astype(np.float64), axis=1)
    squares = np.einsum("nij,nij->n", residual, residual, dtype=np.float64)
    dc = spectrum[:, 0, 0]
    base = squares - (dc.real**2 + dc.imag**2) / pixels  # the baseline absorbs the mean
    left = np.maximum(base[:, None] - removed / pixels, 0.0)  # after 1..width gratings
    budget = goal_rms**2 * owned
    enough = left <= budget[:, None]
    first = np.where(enough.any(axis=1), np.argmax(enough, axis=1) + 1, width)
    count = np.minimum(first, free)
    at_limit = np.take_along_axis(left, np.maximum(limit - 1, 0)[:, None], axis=1)[:, 0]
    rms_at_limit = np.sqrt(np.where(limit > 0, at_limit, base) / np.maximum(owned, 1))
    count, p95 = _grow(spectrum, top, count, free, mask, owned, target)
    ky, kx = np.divmod(top, nw // 2 + 1)
    slot = np.arange(width)[None, :]
    valid = slot < count[:, None]
    rows = np.arange(n)[:, None]
    spectra.fx[:] = kx
    spectra.fy[:] = np.where(ky > nh // 2, ky - nh, ky)
    spectra.coef[:] = np.where(valid, spectrum[rows, ky, kx] / pixels, 0.0)
    spectra.valid[:] = valid
    spectra.mean[:] = dc.real / pixels
    return Pursuit(spectra, count, p95, rms_at_limit)


def _grow(
    spectrum: np.ndarray,
    top: np.ndarray,
    count: np.ndarray,
    free: np.ndarray,
    mask: np.ndarray,
    owned: np.ndarray,
    target: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Check the 95th percentile left by each tile's chosen gratings on its pixels; tiles over
    the target take more (about 1.5 times as many, within their free slots) and are checked
    again. Returns the final counts and percentiles (gray levels)."""
    count = count.copy()
    p95 = np.zeros(count.size)
    todo = np.arange(count.size)
    for round_ in range(_GROWTH_ROUNDS + 1):
        left = _residual_after(spectrum[todo], top[todo], count[todo], mask.shape[1:])
        p95[todo] = masked_percentile(np.abs(left), mask[todo], owned[todo])
        over = p95[todo] > target
        grow = over & (count[todo] < free[todo])
        if round_ == _GROWTH_ROUNDS or not grow.any():
            break
        todo = todo[grow]
        count[todo] = np.minimum(free[todo], count[todo] + np.maximum(count[todo] // 2, 1))
    return count, p95


def _residual_after(
    spectrum: np.ndarray, top: np.ndarray, count: np.ndarray, shape: tuple[int, ...]
) -> np.ndarray:
    """The residual left when the first ``count`` bins of ``top`` (with their mirror images)
    and the mean are removed."""
    kept = spectrum.copy()
    n, nh, nxh = kept.shape
    used = np.arange(top.shape[1])[None, :] < count[:, None]
    rows = np.broadcast_to(np.arange(n)[:, None], top.shape)[used]
    ky, kx = np.divmod(top[used], nxh)
    kept[rows, ky, kx] = 0.0
    # in the columns kx = 0 (and Nyquist) the mirror image (-ky) is stored too
    own_column = (kx == 0) | (2 * kx == shape[1])
    kept[rows[own_column], (-ky[own_column]) % nh, kx[own_column]] = 0.0
    kept[:, 0, 0] = 0.0
    return irfft2(kept, (shape[0], shape[1]))


def error_figures(residual: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RMS and 95th percentile (nearest rank) of the absolute ``residual`` ``(n, nh, nw)`` over
    each tile's owned pixels (``mask`` as in :func:`pursue`; ``residual`` zero elsewhere)."""
    n = residual.shape[0]
    owned = np.rint(mask.reshape(n, -1).sum(axis=1)).astype(np.int64)
    rms = np.sqrt(np.einsum("nij,nij->n", residual, residual, dtype=np.float64)
                  / np.maximum(owned, 1))
    return rms, masked_percentile(np.abs(residual), mask, owned)


def over_target(residual: np.ndarray, owned: np.ndarray, target: float) -> np.ndarray:
    """``(n,)`` whether the 95th percentile (nearest rank) of the absolute ``residual`` ``(n,
    nh, nw)`` over each tile's ``owned`` pixels exceeds ``target``: more than ``owned - rank``
    of them do (the residual is zero on pixels a tile does not own). No tiles, none over (a
    reshape of zero tiles to ``(0, -1)`` raised: every tile of an image within the target)."""
    n = residual.shape[0]
    if n == 0:
        return np.zeros(0, dtype=bool)
    flat = residual.reshape(n, -1)
    beyond = np.count_nonzero((flat > target) | (flat < -target), axis=1)
    return beyond > owned - (95 * owned + 99) // 100


def masked_percentile(magnitude: np.ndarray, mask: np.ndarray, owned: np.ndarray) -> np.ndarray:
    """95th percentile (nearest rank) of ``magnitude`` ``(n, nh, nw)`` (>= 0) over each tile's
    owned pixels (``mask`` as in :func:`pursue`, ``owned`` its sum per tile)."""
    n = magnitude.shape[0]
    flat = (magnitude * mask).reshape(n, -1)  # unowned pixels sort first
    size = flat.shape[1]
    out = np.zeros(n)
    for value in counts_present(owned):
        tiles = np.nonzero(owned == value)[0]
        if value == 0:
            continue
        kth = size - int(value) + percentile_rank(int(value)) - 1
        out[tiles] = np.partition(flat[tiles], kth, axis=1)[:, kth]
    return out
