"""Per-taxtel windowed 2-D spectral analysis, vectorised over all tiles at once.

For every tile (``tile_h x tile_w`` pixels, see :mod:`.geometry`):

1. mean and standard deviation of the gray levels; a tile whose standard deviation is below the
   smallest amplitude kept is near uniform and keeps its mean only (no spectrum is computed);
2. a 2-D periodic Hann window and one batched real FFT of the other tiles
   (:func:`.fft.rfft2`); the windowed mean leaks into the DC bin and its neighbours only,
   and is removed from them;
3. peak picking in the half plane: bins above a magnitude threshold (set by the smallest
   amplitude kept), outside the DC bin and its neighbours and off the Nyquist row and column,
   that are local maxima of their 3 x 3 neighbourhood; the strongest ``n_peaks`` per tile;
4. the fractional frequency of each peak from the magnitudes of its neighbours along each axis.
   For a periodic Hann window the magnitude ratio of two adjacent bins fixes the offset
   (``delta = (2a - 1) / (a + 1)`` for a continuous spectrum); a Newton step on the exact
   (Dirichlet) window kernel removes the finite-size error. This is more accurate than Gaussian
   interpolation and needs no zero padding, which keeps the FFT at the size of the image;
5. one CLEAN-style pass: the frequencies are measured again after the tile's other components
   and all mirror images (the signal is real) are subtracted from each peak's bins, using the
   model of step 4, which removes the bias a strong grating puts on a weak one;
6. amplitude and phase of all peaks of a tile jointly by least squares on the peak bins, with
   the exact window kernel, so that leakage between close components is accounted for.

Work is batched over tiles; loops run over component counts and bin offsets only. Frequencies
here are in cycles per tile ("bins"); :func:`to_surface` converts them to cycles/mm and the
phases to the surface origin.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from hcard import limits

from .fft import rfft2
from .geometry import Geometry
from .textures import Textures, canonical, strongest_first

MIN_TILE_PX = 4
"""Tiles smaller than this (pixels, either axis) are analysed for their mean only."""
_NEWTON_STEPS = 1
"""Newton steps on the exact kernel after the closed-form offset (whose error is < 1e-3 bin)."""
_CLEAN_PASSES = 1
"""Frequency re-measurements with the other components and the mirror images removed."""
_RIDGE = 1e-3
"""Tikhonov weight of the amplitude solve, relative to the window's peak gain."""
_SCALLOP = 0.6
"""Lower bound on |peak bin| / (A/2 * sum(window)): Hann loses at most 0.85 per axis."""


@dataclass
class TileSpectra:
    """Result of :func:`analyse_tiles` for ``n`` tiles and up to ``k`` components each.

    All values are in the units of the gray levels given (0 = black) and tile-local:

    Attributes:
        mean: ``(n,)`` mean gray level of each tile.
        std: ``(n,)`` standard deviation of the gray levels of each tile.
        fx, fy: ``(n, k)`` frequency of each component, cycles per tile width / height; ``fx``
            is in ``[-0.5, tile_w / 2]`` and ``fy`` signed.
        coef: ``(n, k)`` complex amplitude ``c`` such that the component is
            ``2 * Re(c * exp(2j*pi*(fx*j/tile_w + fy*i/tile_h)))`` at tile pixel (row i, col j);
            ``|c|`` is half the peak amplitude.
        valid: ``(n, k)`` which entries hold a component; valid entries come first, strongest
            first.
    """

    mean: np.ndarray
    std: np.ndarray
    fx: np.ndarray
    fy: np.ndarray
    coef: np.ndarray
    valid: np.ndarray

    @classmethod
    def empty(cls, n: int, k: int) -> TileSpectra:
        """``n`` tiles with no components (means and deviations zero)."""
        return cls(
            mean=np.zeros(n),
            std=np.zeros(n),
            fx=np.zeros((n, k)),
            fy=np.zeros((n, k)),
            coef=np.zeros((n, k), dtype=np.complex128),
            valid=np.zeros((n, k), dtype=bool),
        )

    @classmethod
    def concatenate(cls, parts: list[TileSpectra]) -> TileSpectra:
        """Stack the results of consecutive chunks of tiles."""
        return cls(
            *(
                np.concatenate([getattr(p, name) for p in parts])
                for name in cls.__dataclass_fields__
            )
        )


def hann_window(n: int) -> np.ndarray:
    """Periodic Hann window of ``n`` points, ``0.5 - 0.5 cos(2 pi j / n)``."""
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)


def dirichlet(u: np.ndarray, n: int) -> np.ndarray:
    """``sum_{j<n} exp(2j*pi*u*j/n)`` for real ``u`` (cycles per ``n`` samples), complex."""
    u = np.asarray(u, dtype=np.float64)
    u = u - n * np.round(u / n)  # the sum is periodic in u with period n
    small = np.abs(u) < 1e-9
    safe = np.where(small, 1.0, u)
    value = np.sin(np.pi * safe) / np.sin(np.pi * safe / n)
    value = np.where(small, float(n), value)
    return np.exp(1j * np.pi * u * (n - 1) / n) * value


def hann_kernel(u: np.ndarray, n: int) -> np.ndarray:
    """``sum_{j<n} w_j exp(2j*pi*u*j/n)`` for the periodic Hann window ``w``: the windowed DFT
    of a unit complex exponential at frequency ``f`` seen in bin ``k`` is ``hann_kernel(f-k)``.

    Closed form: ``exp(i pi u (n-1)/n) sin(pi u) [1/2 / sin(pi u/n)
    - 1/4 exp(-i pi/n) / sin(pi (u+1)/n) - 1/4 exp(i pi/n) / sin(pi (u-1)/n)]``.
    """
    return hann_kernels(u, n, (0,))[0]


def hann_kernels(u: np.ndarray, n: int, shifts: tuple[int, ...]) -> dict[int, np.ndarray]:
    """``{j: hann_kernel(u + j, n)}`` for integer shifts ``j``, sharing the trigonometry."""
    u = np.asarray(u, dtype=np.float64)
    # The singularities at integer u are removable: step off them by 2e-7 bin (the kernel is
    # smooth, so its value changes by ~1e-7 relative) instead of evaluating limits.
    u = np.where(np.abs(u - np.round(u)) < 1e-7, u + 2e-7, u)
    angle = (np.pi / n) * u
    s, c = np.sin(angle), np.cos(angle)
    sine = np.sin(np.pi * u)
    phase = np.exp(1j * (np.pi * (n - 1) / n) * u)
    lower, upper = np.exp(-1j * np.pi / n), np.exp(1j * np.pi / n)
    denominators: dict[int, np.ndarray] = {}

    def sin_at(k: int) -> np.ndarray:  # sin(pi (u + k) / n)
        if k not in denominators:
            denominators[k] = s * np.cos(np.pi * k / n) + c * np.sin(np.pi * k / n)
        return denominators[k]

    kernels = {}
    for j in shifts:
        # sin(pi (u + j)) = (-1)^j sin(pi u); the phase factor gains exp(i pi j (n-1)/n).
        factor = (-1.0) ** j * np.exp(1j * np.pi * j * (n - 1) / n)
        bracket = 0.5 / sin_at(j) - 0.25 * lower / sin_at(j + 1) - 0.25 * upper / sin_at(j - 1)
        kernels[j] = (factor * phase) * sine * bracket
    return kernels


def hann_kernels_of(
    pairs: list[tuple[np.ndarray, int]], shifts: tuple[int, ...]
) -> list[dict[int, np.ndarray]]:
    """:func:`hann_kernels` of several ``(u, n)`` at once: the arrays of equal ``n`` and shape
    go through one call (the kernel is elementwise: the same values, fewer numpy calls)."""
    out: list[dict[int, np.ndarray]] = [{} for _ in pairs]
    groups: dict[tuple[int, tuple[int, ...]], list[int]] = {}
    for i, (u, n) in enumerate(pairs):
        groups.setdefault((n, np.shape(u)), []).append(i)
    for (n, _), members in groups.items():
        stacked = hann_kernels(np.stack([pairs[i][0] for i in members]), n, shifts)
        for slot, i in enumerate(members):
            out[i] = {j: kernel[slot] for j, kernel in stacked.items()}
    return out


def analyse_tiles(tiles: np.ndarray, *, n_peaks: int, min_amplitude: float) -> TileSpectra:
    """Spectral analysis of tiles ``(rows, tile_h, cols, tile_w)`` (any real dtype).

    Args:
        tiles: gray levels, tile (r, c) is ``tiles[r, :, c, :]``.
        n_peaks: largest number of components per tile.
        min_amplitude: smallest amplitude worth finding, gray-level units. It sets the peak
            detection threshold, and tiles whose standard deviation is below it are near
            uniform: they get their mean only (no spectrum is computed for them).

    Returns:
        Results for the ``rows * cols`` tiles in row-major order.
    """
    rows, nh, cols, nw = tiles.shape
    n_tiles = rows * cols
    pixels = nh * nw
    # 8-bit sums of squares stay well inside float32 precision; wider data accumulate in float64.
    accumulate = np.float32 if tiles.dtype == np.uint8 else np.float64
    total = np.einsum("aibj->ab", tiles, dtype=accumulate).ravel().astype(np.float64)
    squares = np.einsum("aibj,aibj->ab", tiles, tiles, dtype=accumulate).ravel()
    mean = total / pixels
    std = np.sqrt(np.maximum(squares.astype(np.float64) / pixels - mean * mean, 0.0))
    result = TileSpectra.empty(n_tiles, max(n_peaks, 0))
    result.mean, result.std = mean, std
    if n_peaks <= 0 or nh < MIN_TILE_PX or nw < MIN_TILE_PX:
        return result
    active = np.flatnonzero(std >= min_amplitude)
    if active.size == 0:
        return result
    window = (hann_window(nh)[:, None] * hann_window(nw)[None, :]).astype(np.float32)
    block = np.multiply(tiles.transpose(0, 2, 1, 3)[active // cols, active % cols], window)
    spectrum = rfft2(block)  # (active, nh, nw // 2 + 1)
    del block
    _remove_mean_leak(spectrum, nh, nw)
    local = _analyse_spectra(spectrum, nw, n_peaks, min_amplitude)
    if local is not None:
        result.fx[active], result.fy[active] = local.fx, local.fy
        result.coef[active], result.valid[active] = local.coef, local.valid
    return result


def _analyse_spectra(
    spectrum: np.ndarray, nw: int, n_peaks: int, min_amplitude: float
) -> TileSpectra | None:
    """Components of windowed tile spectra ``(n, nh, nw // 2 + 1)``; ``None`` if there are none."""
    n, nh, _ = spectrum.shape
    magnitude = np.abs(spectrum)
    threshold = 0.5 * min_amplitude * _SCALLOP * (nh / 2.0) * (nw / 2.0)
    peaks = _pick_peaks(magnitude, nw, threshold, n_peaks)
    if peaks is None:
        return None
    tile, ky, kx, rank = peaks
    centre = magnitude[tile, ky, kx].astype(np.float64)
    # First estimate (closed form); the refinement below re-measures with the exact kernel.
    dx = _offset(
        _mag(magnitude, tile, ky, kx - 1, nw), centre, _mag(magnitude, tile, ky, kx + 1, nw), nw, 0
    )
    dy = _offset(
        _mag(magnitude, tile, ky - 1, kx, nw), centre, _mag(magnitude, tile, ky + 1, kx, nw), nh, 0
    )
    ky_signed = np.where(ky > nh // 2, ky - nh, ky)
    local = TileSpectra.empty(n, n_peaks)
    local.fx[tile, rank] = np.clip(kx + dx, -0.5, nw / 2.0)
    local.fy[tile, rank] = np.clip(ky_signed + dy, -nh / 2.0, nh / 2.0)
    local.valid[tile, rank] = True
    peak_x = np.zeros((n, n_peaks), dtype=np.int64)
    peak_y = np.zeros((n, n_peaks), dtype=np.int64)
    values = np.zeros((n, n_peaks), dtype=np.complex128)
    peak_x[tile, rank], peak_y[tile, rank] = kx, ky_signed
    values[tile, rank] = spectrum[tile, ky, kx]
    # Starting amplitudes: each peak bin divided by its own window gain.
    kx_gain, ky_gain = hann_kernels_of([(local.fx - peak_x, nw), (local.fy - peak_y, nh)], (0,))
    gain = kx_gain[0] * ky_gain[0]
    local.coef = np.where(local.valid, values / np.where(local.valid, gain, 1.0), 0.0)
    for _ in range(_CLEAN_PASSES):
        _refine_frequencies(local, spectrum, peak_x, peak_y, nw)
    local.coef = _solve_amplitudes(local, peak_x, peak_y, values, nh, nw)
    return local


def _bin(
    spectrum: np.ndarray, tile: np.ndarray, ky: np.ndarray, kx: np.ndarray, nw: int
) -> np.ndarray:
    """Complex value at any integer bin (outside the stored half plane: ``X(-k) = conj X(k)``)."""
    nh = spectrum.shape[1]
    kxm = np.mod(kx, nw)
    kym = np.mod(ky, nh)
    flip = kxm > nw // 2
    kxm = np.where(flip, nw - kxm, kxm)
    kym = np.where(flip, np.mod(-kym, nh), kym)
    value = spectrum[tile, kym, kxm].astype(np.complex128)
    return np.where(flip, np.conj(value), value)


_GROUP_WIDTHS = (1, 2, 4, 8, 16)
"""Tiles are processed in groups of similar component counts, padded to these widths: few
batched calls, little padding."""


def _groups(valid: np.ndarray) -> Iterator[tuple[np.ndarray, int, np.ndarray]]:
    """``(tiles, width, mask)`` batches of tiles with 1..width components (valid slots first);
    ``mask`` ``(n, width)`` marks the real components of each tile."""
    count = valid.sum(axis=1)
    lower = 1
    for width in _GROUP_WIDTHS:
        width = min(width, valid.shape[1])
        tiles = np.nonzero((count >= lower) & (count <= width))[0]
        if tiles.size:
            yield tiles, width, valid[tiles, :width]
        lower = width + 1
        if width == valid.shape[1]:
            break


_LOOKS = ((0, 0), (0, -1), (0, 1), (-1, 0), (1, 0))
"""Bins :func:`_refine_frequencies` looks at, ``(dy, dx)`` from a component's peak bin."""
_LOOK_Y = np.array([dy for dy, _ in _LOOKS])[:, None, None]
_LOOK_X = np.array([dx for _, dx in _LOOKS])[:, None, None]


def _stack_shifts(kernels: dict[int, np.ndarray], looks: np.ndarray) -> np.ndarray:
    """``kernels[-o]`` for each offset ``o`` of ``looks`` (the bin shifted by ``o`` sees the
    kernel shifted by ``-o``), stacked on a new first axis."""
    return np.stack([kernels[-int(o)] for o in looks.ravel()])


def _refine_frequencies(
    spectra: TileSpectra, spectrum: np.ndarray, peak_x: np.ndarray, peak_y: np.ndarray, nw: int
) -> None:
    """Re-measure the frequencies of every component after removing the tile's other
    components and every mirror image from its peak bin and neighbours, using the current model.

    A strong grating leaks a little into the bins of a weak one, and a grating close to an axis
    into its own mirror image; this removes the bias to first order.
    """
    nh = spectrum.shape[1]
    for tiles, m, mask in _groups(spectra.valid):
        fx, fy, coef = spectra.fx[tiles, :m], spectra.fy[tiles, :m], spectra.coef[tiles, :m]
        coef = np.where(mask, coef, 0.0)  # padding slots contribute nothing
        px, py = peak_x[tiles, :m], peak_y[tiles, :m]
        t = np.broadcast_to(tiles[:, None], px.shape)
        own = np.eye(m, dtype=bool)[None, :, :]
        # 1-D kernels [t, j, k] (source k seen from peak j's bin shifted by o), for the
        # direct components and their mirror images; shared by the five bins looked at.
        # hann_kernels(u)[j] is H(u + j): the bin shifted by o is the kernel shifted by -o.
        shifts = (-1, 0, 1)
        x_direct, y_direct, x_mirror, y_mirror = hann_kernels_of(
            [(fx[:, None, :] - px[:, :, None], nw), (fy[:, None, :] - py[:, :, None], nh),
             (-fx[:, None, :] - px[:, :, None], nw), (-fy[:, None, :] - py[:, :, None], nh)],
            shifts,
        )
        source, image = coef[None, :, None, :], np.conj(coef)[None, :, None, :]
        # The five bins at once, axis 0 in the order of _LOOKS: (t, j) per bin.
        measured = _bin(spectrum, t, py + _LOOK_Y, px + _LOOK_X, nw)
        direct = source * _stack_shifts(x_direct, _LOOK_X) * _stack_shifts(y_direct, _LOOK_Y)
        mirror = image * _stack_shifts(x_mirror, _LOOK_X) * _stack_shifts(y_mirror, _LOOK_Y)
        others = np.where(own, 0.0, direct).sum(axis=3) + mirror.sum(axis=3)
        cleaned = measured - others
        cleaned_centre = cleaned[0]
        magnitude = np.abs(cleaned)
        centre = np.maximum(magnitude[0], 1e-30)
        dx = _offset(magnitude[1], centre, magnitude[2], nw, _NEWTON_STEPS)
        dy = _offset(magnitude[3], centre, magnitude[4], nh, _NEWTON_STEPS)
        fx = np.where(mask, np.clip(px + dx, -0.5, nw / 2.0), 0.0)
        fy = np.where(mask, np.clip(py + dy, -nh / 2.0, nh / 2.0), 0.0)
        spectra.fx[tiles, :m], spectra.fy[tiles, :m] = fx, fy
        # Amplitudes for the next pass: own bin over own gain at the new frequency.
        kx_gain, ky_gain = hann_kernels_of([(fx - px, nw), (fy - py, nh)], (0,))
        gain = kx_gain[0] * ky_gain[0]
        spectra.coef[tiles, :m] = np.where(mask, cleaned_centre / gain, 0.0)


def _remove_mean_leak(spectrum: np.ndarray, nh: int, nw: int) -> None:
    """Subtract the windowed tile mean from the bins it leaks into (DC and its neighbours).

    A constant ``m`` under a periodic Hann window appears only in bins with ``|k| <= 1`` on both
    axes, as ``m * W(-ky) * W(-kx)`` with ``W(0) = n/2`` and ``W(+-1) = -n/4``.
    """
    level = spectrum[:, 0, 0].real / (nh * nw / 4.0)
    wy = {0: nh / 2.0, 1: -nh / 4.0, -1: -nh / 4.0}
    wx = {0: nw / 2.0, 1: -nw / 4.0}
    for ky, fy in wy.items():
        for kx, fx in wx.items():
            spectrum[:, ky, kx] -= (level * (fy * fx)).astype(spectrum.real.dtype)


def _mag(
    magnitude: np.ndarray, tile: np.ndarray, ky: np.ndarray, kx: np.ndarray, nw: int
) -> np.ndarray:
    """Magnitude at any integer bin of tiles ``nw`` pixels wide; ``kx`` may fall outside the
    stored half plane (the spectrum of a real tile has ``|X(-k)| = |X(k)|``)."""
    nh = magnitude.shape[1]
    kxm = np.mod(kx, nw)
    kym = np.mod(ky, nh)
    flip = kxm > nw // 2
    kxm = np.where(flip, nw - kxm, kxm)
    kym = np.where(flip, np.mod(-kym, nh), kym)
    return magnitude[tile, kym, kxm].astype(np.float64)


def _pick_peaks(
    magnitude: np.ndarray, nw: int, threshold: float, n_peaks: int
) -> tuple[np.ndarray, ...] | None:
    """Local maxima above ``threshold`` in the half plane, the ``n_peaks`` strongest per tile.

    Returns ``(tile, ky, kx, rank)`` index arrays (``ky`` as stored, 0..nh-1) or ``None``.
    """
    _, nh, nxh = magnitude.shape
    candidate = magnitude > threshold
    # Not components: the DC bin and its neighbours (mean and its window leakage).
    candidate[:, 0:2, 0:2] = False
    candidate[:, nh - 1, 0:2] = False
    # Mirror duplicates in the half plane: kx = 0 with ky < 0.
    candidate[:, nh // 2 + 1 :, 0] = False
    # The Nyquist row and column: a grating there has no defined phase (its mirror image
    # falls on the same bin), so it cannot be measured.
    if nw % 2 == 0:
        candidate[:, :, nxh - 1] = False
    if nh % 2 == 0:
        candidate[:, nh // 2, :] = False
    flat = np.flatnonzero(candidate)  # much faster than a 3-D nonzero
    if flat.size == 0:
        return None
    value = magnitude.reshape(-1)[flat]
    kx = flat % nxh
    rest = flat // nxh
    ky = rest % nh
    tile = rest // nh
    # Nearest neighbours first: they eliminate most candidates, so later tests see fewer.
    for dy, dx in ((0, -1), (0, 1), (-1, 0), (1, 0), (-1, -1), (-1, 1), (1, -1), (1, 1)):
        other = _mag(magnitude, tile, ky + dy, kx + dx, nw)
        # Ties: the bin earlier in raster order wins, so a flat top yields one peak.
        keep = (value > other) if (dy, dx) < (0, 0) else (value >= other)
        tile, ky, kx, value = tile[keep], ky[keep], kx[keep], value[keep]
    if tile.size == 0:
        return None
    order = np.lexsort((-value, tile))
    tile_sorted = tile[order]
    rank = np.arange(order.size) - np.searchsorted(tile_sorted, tile_sorted, side="left")
    keep = rank < n_peaks
    order, rank = order[keep], rank[keep]
    return tile[order], ky[order], kx[order], rank


def _offset(
    minus: np.ndarray, centre: np.ndarray, plus: np.ndarray, n: int, newton_steps: int
) -> np.ndarray:
    """Fractional offset of a spectral peak from its bin, in bins, from the magnitudes of the
    bin and its two neighbours along one axis (periodic Hann window of ``n`` points)."""
    right = plus >= minus
    ratio = np.clip(np.where(right, plus, minus) / centre, 0.0, 1.0)
    delta = np.clip((2.0 * ratio - 1.0) / (ratio + 1.0), 0.0, 0.5)
    step = 1e-4
    for _ in range(newton_steps):
        # |H(d - 1)| - ratio |H(d)| at d = delta and delta + step: one kernel evaluation.
        kernels = hann_kernels(np.stack([delta, delta + step]), n, (-1, 0))
        gap = np.abs(kernels[-1]) - ratio * np.abs(kernels[0])
        residual = gap[0]
        slope = (gap[1] - residual) / step
        safe = np.where(np.abs(slope) > 1e-12, slope, 1.0)
        delta = np.clip(delta - residual / safe, 0.0, 0.5)
    return np.where(right, delta, -delta)


def _solve_amplitudes(
    spectra: TileSpectra,
    peak_x: np.ndarray,
    peak_y: np.ndarray,
    values: np.ndarray,
    nh: int,
    nw: int,
) -> np.ndarray:
    """Complex amplitudes of all components of each tile, solved jointly on the peak bins.

    Bin ``p_j`` holds ``sum_k c_k H(f_k - p_j) + conj(c_k) H(-f_k - p_j)`` with the 2-D window
    kernel ``H``; this is linear in (Re c, Im c). Tiles are grouped by their number of
    components, so each group is one batched solve; padding slots get amplitude 0.
    """
    coef = np.zeros(spectra.valid.shape, dtype=np.complex128)
    ridge = (_RIDGE * (nh / 2.0) * (nw / 2.0)) ** 2
    for tiles, m, mask in _groups(spectra.valid):
        fx, fy = spectra.fx[tiles, :m], spectra.fy[tiles, :m]
        px, py = peak_x[tiles, :m], peak_y[tiles, :m]
        # [t, j, k]: component k seen in the peak bin of component j (zero for padding).
        pair = mask[:, :, None] & mask[:, None, :]
        x_direct, y_direct, x_mirror, y_mirror = hann_kernels_of(
            [(fx[:, None, :] - px[:, :, None], nw), (fy[:, None, :] - py[:, :, None], nh),
             (-fx[:, None, :] - px[:, :, None], nw), (-fy[:, None, :] - py[:, :, None], nh)],
            (0,),
        )
        direct = x_direct[0] * y_direct[0]
        mirror = x_mirror[0] * y_mirror[0]
        direct, mirror = np.where(pair, direct, 0.0), np.where(pair, mirror, 0.0)
        plus, minus = direct + mirror, direct - mirror
        system = np.block([[plus.real, -minus.imag], [plus.imag, minus.real]])
        bins = np.where(mask, values[tiles, :m], 0.0)
        rhs = np.concatenate([bins.real, bins.imag], axis=1)
        # Regularised normal equations: a direction the bins cannot see (two components on
        # one bin) gets amplitude 0 instead of an arbitrary one.
        normal = np.matmul(system.transpose(0, 2, 1), system)
        normal += ridge * np.eye(2 * m)
        projected = np.matmul(system.transpose(0, 2, 1), rhs[:, :, None])
        solution = np.linalg.solve(normal, projected)[:, :, 0]
        coef[tiles, :m] = solution[:, :m] + 1j * solution[:, m:]
    return coef


def to_surface(
    spectra: TileSpectra,
    geometry: Geometry,
    *,
    high: float,
    low: float,
    scale: float,
    min_amplitude: float,
    max_frequency: float = limits.MAX_SPATIAL_FREQUENCY,
    first_row: int = 0,
) -> Textures:
    """Per-taxtel textures in surface units from the tile-local analysis.

    Gray levels map to relative friction as ``high - scale * gray`` (black = ``high``, white =
    ``low``).
    Frequencies become cycles/mm per axis (pixels may be rectangular), phases move from the
    tile's first pixel to the surface origin, and the orientation is made canonical.
    Components weaker than ``min_amplitude`` (relative friction) or above ``max_frequency``
    (cycles/mm) are dropped, and so are all components of a taxtel whose friction standard
    deviation is below ``min_amplitude``. The baseline is the taxtel's mean friction minus the
    mean of its kept components over the tile, clipped to the friction range.
    ``spectra`` holds whole taxtel rows, from row ``first_row`` on.
    """
    nh, nw = geometry.tile_h, geometry.tile_w
    tile_row, tile_col = np.divmod(np.arange(spectra.mean.size), geometry.cols)
    tile_row += first_row
    kx = spectra.fx * (geometry.ppx / nw)
    ky = spectra.fy * (geometry.ppy / nh)
    x0 = (geometry.col_tile[tile_col] + 0.5) / geometry.ppx
    y0 = (geometry.row_tile[tile_row] + 0.5) / geometry.ppy
    gray_coef = 2.0 * spectra.coef * np.exp(-2j * np.pi * (kx * x0[:, None] + ky * y0[:, None]))
    coef = -scale * gray_coef
    valid = (
        spectra.valid
        & (np.abs(coef) >= min_amplitude)
        & (np.hypot(kx, ky) <= max_frequency)
        & (scale * spectra.std >= min_amplitude)[:, None]
    )
    # Mean of each kept component over its tile (non-integer cycles per tile do not average out).
    tile_mean = (
        2.0
        * (spectra.coef * dirichlet(spectra.fx, nw) * dirichlet(spectra.fy, nh)).real
        / (nh * nw)
    )
    mean = spectra.mean - np.sum(np.where(valid, tile_mean, 0.0), axis=1)
    baseline = np.clip(high - scale * mean, low, high)
    k = np.stack([kx, ky], axis=-1)
    textures = Textures(baseline, k, np.where(valid, coef, 0.0), valid)
    return strongest_first(canonical(textures))


def tile_centres(geometry: Geometry) -> np.ndarray:
    """``(n_taxtels, 2)`` centres of the analysis tiles, millimetres, row-major."""
    tile_row = np.repeat(np.arange(geometry.rows), geometry.cols)
    tile_col = np.tile(np.arange(geometry.cols), geometry.rows)
    x = (geometry.col_tile[tile_col] + geometry.tile_w / 2.0) / geometry.ppx
    y = (geometry.row_tile[tile_row] + geometry.tile_h / 2.0) / geometry.ppy
    return np.stack([x, y], axis=-1)
