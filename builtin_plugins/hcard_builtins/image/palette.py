"""Texture palette: merge similar taxtel textures, as an indexed-colour image merges colours.

The distance between two textures is the RMS difference of their friction fields. Two
gratings whose wave vectors differ by more than a frequency bin (``w = 1 / taxtel`` cycles/mm)
are orthogonal: their product averages out over a taxtel. It is computed in one of two ways:

- *matched* (textures from the spectral analysis alone, whose components lie bins apart): two
  components match when their wave vectors differ by less than one bin; ``k`` also matches
  ``-k`` with the conjugate amplitude (the same grating written the other way round):

      d^2 = (b1 - b2)^2 + E1/2 + E2/2 - sum_matched Re(C1 conj C2),    E = sum A^2;

- *keyed* (textures that also hold the harmonics of the residual pursuit, which lie exactly
  one bin apart and close to the analysis' gratings): wave vectors closer than a tenth of a bin
  are first given one common value (:func:`align_wave_vectors`), each texture's components
  with equal wave vectors are summed into one (:func:`merge_coincident`), and two components
  overlap only when their wave vectors are equal. A texture is then a sparse vector of
  amplitudes indexed by wave vector, and

      d^2 = (b1 - b2)^2 + 1/2 sum_k |C1(k) - C2(k)|^2

  is a true (Euclidean) distance, zero between a texture and itself, whose cost from one
  texture to all others is O(textures + components sharing one of its wave vectors): the
  components are kept sorted by wave vector and found by bisection. (The matched formula
  counts a pair twice when a texture holds two components within a bin of each other.)

Clustering, all vectorised over taxtels (loops run over leaders, palette entries and component
slots, never over taxtels):

1. leader clustering, farthest first: the first taxtel leads; the taxtel farthest beyond its
   tolerance from every leader becomes the next leader while there is one, so every taxtel ends
   within its tolerance of its leader (at most :func:`leader_cap` leaders). The tolerance may
   differ per taxtel: a taxtel whose own texture already uses most of the error target may
   differ less from the texture it shares;
2. agglomerative merging of the closest pair of clusters (the larger cluster's leader stays
   representative) until at most ``max_textures`` remain; taxtels then join their nearest
   representative;
3. each palette texture is the centroid of its cluster around its representative: the mean
   baseline and, for each component of the representative, the mean complex amplitude of the
   matching components of the members (0 for members without one). The members' phases are
   compared in their own taxtels, and the common wave vector is refined from how their phase
   advances across the surface, so that one texture stays in phase over a large area.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .textures import Textures, canonical, strongest_first

FINE_CELL = 0.01
"""Alignment cell (bins) of the textures fitted as a whole to their taxtel: a shift of 1/200
bin moves a component by 1/400 cycle at the taxtel's edge."""
KEY_RESOLUTION = 1e-6
"""Wave vectors are compared as integers of this many cycles/mm (after alignment, equal wave
vectors are equal floats; the rounding only makes them hashable)."""
_KEY_SPAN = 1 << 28
"""Key of a wave vector: ``x * SPAN + (y + SPAN / 2)`` in units of :data:`KEY_RESOLUTION`; the
format's 50 cycles/mm is 5e7 units, below ``SPAN / 2``."""


@dataclass
class Palette:
    """The merged textures and which one every taxtel plays.

    Attributes:
        textures: the palette, at most ``max_textures`` entries.
        index: ``(n_taxtels,)`` palette entry of every taxtel (row-major).
        leaders: number of clusters found by the leader stage before agglomerative merging.
    """

    textures: Textures
    index: np.ndarray
    leaders: int


def wave_vector_keys(textures: Textures) -> np.ndarray:
    """``(n, m)`` integer key of every slot's wave vector (canonical orientation assumed);
    -1 for empty slots."""
    units = np.rint(textures.k / KEY_RESOLUTION).astype(np.int64)
    key = units[..., 0] * _KEY_SPAN + (units[..., 1] + _KEY_SPAN // 2)
    return np.where(textures.valid, key, -1)


def merge_coincident(textures: Textures) -> Textures:
    """The same textures with the components of one texture that share a wave vector (same
    key) summed into the first of them: the same friction field, one amplitude per grating."""
    key = wave_vector_keys(textures)
    coef, valid = textures.coef.copy(), textures.valid.copy()
    rows = np.arange(key.shape[0])
    for j in range(1, key.shape[1]):
        same = (key[:, :j] == key[:, j : j + 1]) & valid[:, :j] & valid[:, j : j + 1]
        hit = same.any(axis=1)
        if hit.any():
            target = np.argmax(same, axis=1)[hit]
            coef[rows[hit], target] += coef[hit, j]
            valid[hit, j] = False
            coef[hit, j] = 0.0
    return strongest_first(Textures(textures.baseline, textures.k, coef, valid))


_ALL_PAIRS = 16_384
"""Up to this many (query component, component) pairs, all pairs are tested at once: cheaper
than finding the few within a bin first."""


class _Matched:
    """Textures for *matched* distances: one flat list of components (owner, wave vector,
    amplitude), so that the distance from one texture to all of them costs O(components), not
    O(textures * slots)."""

    def __init__(self, textures: Textures, bin_width: float) -> None:
        owner, slot = np.nonzero(textures.valid)
        coef = textures.coef[owner, slot]
        k = textures.k[owner, slot]
        self.textures = textures
        self.bin_width = bin_width
        self.energy = textures.energy
        self.owner, self.kx, self.ky = owner, k[:, 0], k[:, 1]
        self.re, self.im = coef.real, coef.imag
        # components by kx: those within a bin of a wave vector or its mirror image are found
        # by bisection (a superset: |dkx| < w), then tested exactly
        self.by_kx = np.argsort(self.kx, kind="stable")
        self.sorted_kx = self.kx[self.by_kx]

    def distances(self, i: int) -> np.ndarray:
        """``(n,)`` distances from texture ``i`` to every texture of the set."""
        one = self.textures
        own = one.valid[i]
        k0, c0 = one.k[i][own], one.coef[i][own]
        d2 = (one.baseline[i] - one.baseline) ** 2 + 0.5 * (np.sum(np.abs(c0) ** 2)
                                                            + self.energy)
        if c0.size and self.owner.size:
            everything = c0.size * self.owner.size <= _ALL_PAIRS
            near = None if everything else self._near(k0[:, 0])
            if near is None or near.size:
                pick: slice | np.ndarray = slice(None) if near is None else near
                limit = self.bin_width * self.bin_width
                kx, ky = k0[:, 0:1], k0[:, 1:2]  # (q, 1) against the candidates
                cx, cy = self.kx[pick], self.ky[pick]
                direct = (cx - kx) ** 2 + (cy - ky) ** 2 < limit
                mirror = ((cx + kx) ** 2 + (cy + ky) ** 2 < limit) & ~direct
                # Re(c conj C) for a direct match, Re(c C) for a mirrored one.
                same = c0.real[:, None] * self.re[pick]
                cross = c0.imag[:, None] * self.im[pick]
                overlap = np.where(direct, same + cross, np.where(mirror, same - cross, 0.0))
                d2 -= np.bincount(self.owner[pick], weights=overlap.sum(axis=0),
                                  minlength=one.baseline.size)
        return np.sqrt(np.maximum(d2, 0.0))

    def _near(self, kx: np.ndarray) -> np.ndarray:
        """Indices, ascending (the order of the sums above is that of all components), of the
        components whose kx lies within a bin of one of ``kx`` or of its negative."""
        width = self.bin_width
        centres = np.concatenate([kx, -kx])
        lo = np.searchsorted(self.sorted_kx, centres - width, side="left")
        hi = np.searchsorted(self.sorted_kx, centres + width, side="right")
        length = hi - lo
        total = int(length.sum())
        if total == 0:
            return np.zeros(0, dtype=np.int64)
        index = np.repeat(lo - np.cumsum(length) + length, length) + np.arange(total)
        found = np.zeros(self.kx.size, dtype=bool)
        found[self.by_kx[index]] = True
        return np.flatnonzero(found)


class _Keyed:
    """Textures for *keyed* distances: per texture its baseline, energy ``1/2 sum |C|^2`` and
    slots (key, amplitude); and all components in one list sorted by key, so that those
    sharing a wave vector with a given texture are found by bisection."""

    def __init__(self, textures: Textures) -> None:
        key = wave_vector_keys(textures)
        coef = np.where(textures.valid, textures.coef, 0.0)
        owner, slot = np.nonzero(textures.valid)
        flat_key = key[owner, slot]
        order = np.argsort(flat_key, kind="stable")
        flat_coef = coef[owner, slot][order]
        self.textures = textures
        self.baseline = textures.baseline
        self.energy = 0.5 * np.sum(np.abs(coef) ** 2, axis=1)
        self.key, self.coef = key, coef
        self.sorted_key, self.owner = flat_key[order], owner[order]
        self.re, self.im = flat_coef.real, flat_coef.imag

    def distances(self, i: int) -> np.ndarray:
        """``(n,)`` distances from texture ``i`` to every texture of the set: ``(b - b_t)^2 +
        E + E_t`` for all, less the overlap with the components sharing its wave vectors."""
        d2 = (self.baseline[i] - self.baseline) ** 2 + self.energy[i] + self.energy
        own = self.key[i] >= 0
        keys, coef = self.key[i][own], self.coef[i][own]
        if keys.size and self.sorted_key.size:
            lo = np.searchsorted(self.sorted_key, keys, side="left")
            hi = np.searchsorted(self.sorted_key, keys, side="right")
            length = hi - lo
            total = int(length.sum())
            if total:
                which = np.repeat(np.arange(keys.size), length)
                index = np.repeat(lo - np.cumsum(length) + length, length) + np.arange(total)
                overlap = coef.real[which] * self.re[index] + coef.imag[which] * self.im[index]
                d2 -= np.bincount(self.owner[index], weights=overlap,
                                  minlength=self.baseline.size)
        return np.sqrt(np.maximum(d2, 0.0))


_Distances = _Matched | _Keyed


def distances_from(one: Textures, i: int, many: Textures, bin_width: float) -> np.ndarray:
    """RMS friction difference (*matched*) between texture ``i`` of ``one`` and every texture
    of ``many``.

    Args:
        one, i: the reference texture.
        many: textures to compare with (``n`` of them).
        bin_width: matching distance of wave vectors, cycles/mm.

    Returns:
        ``(n,)`` distances in relative friction units.
    """
    both = _concat(one.take(np.array([i])), many)
    return _Matched(both, bin_width).distances(0)[1:]


def keyed_distances_from(one: Textures, i: int, many: Textures, bin_width: float) -> np.ndarray:
    """As :func:`distances_from`, *keyed*: wave vectors aligned (to a tenth of ``bin_width``),
    coincident components summed, components overlapping only at equal wave vectors."""
    both = _concat(one.take(np.array([i])), many)
    centres = np.zeros((both.baseline.size, 2))
    both = merge_coincident(align_wave_vectors(canonical(both), centres, bin_width))
    return _Keyed(both).distances(0)[1:]


def _concat(a: Textures, b: Textures) -> Textures:
    """The textures of ``a`` followed by those of ``b`` (slots padded to the wider)."""
    width = max(a.valid.shape[1], b.valid.shape[1])

    def pad(x: np.ndarray) -> np.ndarray:
        return np.pad(x, [(0, 0), (0, width - x.shape[1])] + [(0, 0)] * (x.ndim - 2))

    return Textures(
        np.concatenate([a.baseline, b.baseline]),
        np.concatenate([pad(a.k), pad(b.k)]),
        np.concatenate([pad(a.coef), pad(b.coef)]),
        np.concatenate([pad(a.valid), pad(b.valid)]),
    )


def leader_cap(max_textures: int) -> int:
    """Most leaders the first stage may create before merging: ``2 * max_textures + 64``."""
    return 2 * max_textures + 64


def build_palette(
    textures: Textures,
    centres: np.ndarray,
    *,
    bin_width: float,
    tolerance: float | np.ndarray,
    max_textures: int,
    min_amplitude: float,
    keyed: bool = False,
    fixed: np.ndarray | None = None,
) -> Palette:
    """Merge per-taxtel ``textures`` into a palette of at most ``max_textures`` entries.

    Args:
        textures: one texture per taxtel.
        centres: ``(n, 2)`` taxtel centres, millimetres (to compare phases locally).
        bin_width: frequency resolution, cycles/mm (``1 / taxtel_mm``).
        tolerance: leader-clustering radius, relative friction (RMS): one for all taxtels or
            ``(n,)``, one per taxtel.
        max_textures: palette size limit.
        min_amplitude: components of the merged textures weaker than this are dropped.
        keyed: *keyed* distances (see the module docstring) rather than *matched* ones; for
            textures holding harmonics of the residual pursuit.
        fixed: ``(n,)`` taxtels whose wave vectors are not aligned (see
            :func:`align_wave_vectors`).
    """
    if max_textures < 1:
        raise ValueError(f"max_textures must be at least 1, got {max_textures}")
    textures = align_wave_vectors(textures.trimmed(), centres, bin_width, fixed=fixed)
    if fixed is not None and fixed.any():
        textures = align_wave_vectors(textures, centres, bin_width, cell=FINE_CELL,
                                      fixed=~fixed)
    space: _Distances
    if keyed:
        textures = merge_coincident(textures)
        space = _Keyed(textures)
    else:
        space = _Matched(textures, bin_width)
    leaders, assign, rows = _leaders(space, tolerance, leader_cap(max_textures))
    found = len(leaders)
    if found > max_textures:
        kept = _agglomerate(rows[:, leaders], assign, max_textures, ward=keyed)
        heads = [leaders[i] for i in kept]
        assign = np.argmin(rows[kept], axis=0)  # the nearest representative of every taxtel
    else:
        heads = leaders
    # Keep the representatives in use (a tie may leave one without taxtels), ordered by their
    # first use in row-major taxtel order.
    first_use = np.full(len(heads), assign.size, dtype=np.int64)
    np.minimum.at(first_use, assign, np.arange(assign.size))
    used = np.nonzero(first_use < assign.size)[0]
    order = used[np.argsort(first_use[used], kind="stable")]
    rank = np.full(len(heads), -1, dtype=np.int64)
    rank[order] = np.arange(order.size)
    representatives = np.asarray(heads)[order]
    assign = rank[assign]
    # Keyed textures lie whole bins apart (the harmonics): a member matches within half a bin.
    radius = 0.5 * bin_width if keyed else bin_width
    merged = _centroids(textures, centres, representatives, assign, radius, min_amplitude)
    return Palette(merged, assign, found)


def align_wave_vectors(
    textures: Textures,
    centres: np.ndarray,
    bin_width: float,
    cell: float = 0.1,
    fixed: np.ndarray | None = None,
) -> Textures:
    """Give components of (nearly) the same wave vector in different taxtels one common value.

    Each taxtel measures its gratings' wave vectors with a small error; extrapolating its phase
    to the surface origin multiplies that error by the distance, so identical gratings far from
    the origin would look different. Components whose wave vectors fall in the same cell of
    ``cell * bin_width`` cycles/mm get the amplitude-weighted mean wave vector of the cell, and
    their phases are re-referenced so that they do not change at their taxtel's centre.
    Textures marked ``fixed`` (``(n,)`` booleans) keep their wave vectors and take no part: a
    texture fitted as a whole to its taxtel (the residual pursuit's) would drift off its fit
    (:func:`build_palette` aligns those among themselves in cells of :data:`FINE_CELL`).
    """
    valid = textures.valid if fixed is None else textures.valid & ~fixed[:, None]
    if not valid.any():
        return textures
    k = textures.k[valid]
    coef = textures.coef[valid]
    position = np.broadcast_to(centres[:, None, :], textures.k.shape)[valid]
    _, group = np.unique(np.round(k / (cell * bin_width)), axis=0, return_inverse=True)
    group = group.ravel()
    weight = np.abs(coef)
    total = np.bincount(group, weights=weight)
    mean = np.stack(
        [np.bincount(group, weights=weight * k[:, axis]) / total for axis in range(2)], axis=-1
    )
    common = mean[group]
    shifted = coef * np.exp(2j * np.pi * np.einsum("nd,nd->n", k - common, position))
    new_k, new_coef = textures.k.copy(), textures.coef.copy()
    new_k[valid], new_coef[valid] = common, shifted
    return Textures(textures.baseline, new_k, new_coef, textures.valid)


def _leaders(
    space: _Distances, tolerance: float | np.ndarray, cap: int
) -> tuple[list[int], np.ndarray, np.ndarray]:
    """Farthest-first leader clustering (farthest beyond its own tolerance); returns leader
    taxtels, each taxtel's leader slot and the distances from each leader to every taxtel
    (``(leaders, n)``: merging and the final assignment read them instead of recomputing)."""
    leaders = [0]
    rows = [space.distances(0)]
    best = rows[0].copy()
    assign = np.zeros(best.size, dtype=np.int64)
    while len(leaders) < cap:
        beyond = best - tolerance
        j = int(np.argmax(beyond))
        if beyond[j] <= 0.0:
            break
        distance = space.distances(j)
        closer = distance < best
        best[closer] = distance[closer]
        assign[closer] = len(leaders)
        leaders.append(j)
        rows.append(distance)
    return leaders, assign, np.stack(rows)


def _agglomerate(
    distance: np.ndarray, assign: np.ndarray, max_textures: int, ward: bool = False
) -> list[int]:
    """Merge the closest pair of leader clusters until ``max_textures`` remain (the first
    closest pair in row-major order of the leaders' distance matrix ``distance``; the lighter
    cluster goes). Returns the indices of the leaders kept.

    With ``ward``, "closest" is the smallest added squared error, ``w_i w_j / (w_i + w_j)
    d_ij^2`` for clusters of ``w_i`` and ``w_j`` taxtels (Ward's criterion): two large clusters
    are merged only when they are much closer than two small ones."""
    count = distance.shape[0]
    distance = distance.copy()
    np.fill_diagonal(distance, np.inf)
    weight = np.bincount(assign, minlength=count).astype(np.float64)
    if ward:
        return _agglomerate_ward(distance, weight, max_textures)
    # Row minima are kept up to date instead of searching the whole matrix at every merge.
    nearest = np.argmin(distance, axis=1)
    closest = distance[np.arange(count), nearest]
    for _ in range(count - max_textures):
        i = int(np.argmin(closest))
        j = int(nearest[i])
        keep, drop = (i, j) if weight[i] >= weight[j] else (j, i)
        weight[keep] += weight[drop]
        weight[drop] = 0.0
        distance[drop, :] = np.inf
        distance[:, drop] = np.inf
        closest[drop] = np.inf
        stale = np.flatnonzero((nearest == drop) & np.isfinite(closest))
        if stale.size:
            nearest[stale] = np.argmin(distance[stale], axis=1)
            closest[stale] = distance[stale, nearest[stale]]
    return [int(i) for i in np.nonzero(weight > 0)[0]]


def _agglomerate_ward(
    distance: np.ndarray, weight: np.ndarray, max_textures: int
) -> list[int]:
    """:func:`_agglomerate` by Ward's criterion on the leaders' distance matrix (the kept
    leader stays representative, so only the weights change and one row of costs with them)."""
    count = distance.shape[0]
    squared = np.where(np.isfinite(distance), distance, 0.0) ** 2

    def pair_weight(a: np.ndarray | float, b: np.ndarray) -> np.ndarray:
        """``a b / (a + b)``; 0 where both are 0 (a leader left without taxtels costs
        nothing to merge)."""
        total = a + b
        return np.divide(a * b, total, out=np.zeros(np.shape(total)), where=total > 0)

    cost = pair_weight(weight[:, None], weight[None, :]) * squared
    np.fill_diagonal(cost, np.inf)
    for _ in range(count - max_textures):
        i, j = np.unravel_index(int(np.argmin(cost)), cost.shape)
        keep, drop = (i, j) if weight[i] >= weight[j] else (j, i)
        weight[keep] += weight[drop]
        weight[drop] = 0.0
        cost[drop, :] = np.inf
        cost[:, drop] = np.inf
        alive = np.isfinite(cost[keep])
        row = pair_weight(weight[keep], weight) * squared[keep]
        cost[keep, alive] = row[alive]
        cost[alive, keep] = row[alive]
    return [int(i) for i in np.nonzero(weight > 0)[0]]


def _centroids(
    textures: Textures,
    centres: np.ndarray,
    representatives: np.ndarray,
    assign: np.ndarray,
    radius: float,
    min_amplitude: float,
) -> Textures:
    """Palette textures: each cluster's mean baseline and mean matched components (taxtels
    whose ``assign`` is negative belong to no cluster)."""
    n_palette = representatives.size
    heads = textures.take(representatives).trimmed()
    if (assign < 0).any():
        keep = np.flatnonzero(assign >= 0)
        textures, centres, assign = textures.take(keep), centres[keep], assign[keep]
    members = np.bincount(assign, minlength=n_palette).astype(np.float64)
    baseline = np.bincount(assign, weights=textures.baseline, minlength=n_palette) / members
    k = heads.k.copy()
    coef = np.zeros(heads.coef.shape, dtype=np.complex128)
    owner, slot = np.nonzero(textures.valid)  # every component of every taxtel, by taxtel
    comp_k, comp_c = textures.k[owner, slot], textures.coef[owner, slot]
    cluster = assign[owner]
    for j in range(heads.valid.shape[1]):
        chosen, k_member, c_member = _match(
            owner, comp_k, comp_c, heads.k[cluster, j], heads.valid[cluster, j], radius
        )
        p, position = cluster[chosen], centres[owner[chosen]]
        k_new = _refine_wave_vector(heads.k[:, j], k_member, c_member, position, p, n_palette)
        k[:, j] = np.where(heads.valid[:, j, None], k_new, k[:, j])
        # Each member's component, seen in its own taxtel, re-expressed with the common k.
        shift = np.einsum("nd,nd->n", k_member - k[p, j], position)
        local = c_member * np.exp(2j * np.pi * shift)
        total = np.bincount(p, weights=local.real, minlength=n_palette) + 1j * np.bincount(
            p, weights=local.imag, minlength=n_palette
        )
        coef[:, j] = total / members
    valid = heads.valid & (np.abs(coef) >= min_amplitude)
    merged = Textures(baseline, k, np.where(valid, coef, 0.0), valid)
    return strongest_first(canonical(merged))


def _match(
    owner: np.ndarray,
    comp_k: np.ndarray,
    comp_c: np.ndarray,
    k_ref: np.ndarray,
    active: np.ndarray,
    radius: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each taxtel, its component nearest to its reference wave vector, within
    ``radius`` (cycles/mm).

    Args:
        owner, comp_k, comp_c: all components (taxtel, wave vector, amplitude), by taxtel.
        k_ref: ``(m, 2)`` reference wave vector for each component's taxtel.
        active: ``(m,)`` whether that taxtel has a reference at all.

    Returns:
        ``(chosen, k, coef)``: indices of the matched components (at most one per taxtel),
        their wave vectors and amplitudes written in the direction of the reference (a mirror
        match ``-k_ref`` is flipped to ``k_ref`` with the conjugate amplitude).
    """
    direct = np.hypot(*(comp_k - k_ref).T)
    mirror = np.hypot(*(comp_k + k_ref).T)
    use_mirror = mirror < direct
    distance = np.where(use_mirror, mirror, direct)
    candidate = np.nonzero(active & (distance < radius))[0]
    order = candidate[np.lexsort((distance[candidate], owner[candidate]))]
    first = np.ones(order.size, dtype=bool)
    first[1:] = owner[order][1:] != owner[order][:-1]
    chosen = order[first]
    sign = np.where(use_mirror[chosen], -1.0, 1.0)
    c = comp_c[chosen]
    return chosen, comp_k[chosen] * sign[:, None], np.where(use_mirror[chosen], np.conj(c), c)


def _refine_wave_vector(
    k_start: np.ndarray,
    k_member: np.ndarray,
    c_member: np.ndarray,
    position: np.ndarray,
    cluster: np.ndarray,
    n_palette: int,
    iterations: int = 2,
) -> np.ndarray:
    """Common wave vector of each cluster's component from its phase across the members.

    Each member measures its component's phase in its own taxtel. With the right common wave
    vector these phases agree; a small error ``dk`` makes them advance as ``2 pi dk . x``. A
    weighted least-squares plane through the phase residuals (weights: amplitudes) estimates
    ``dk``; a weak prior keeps clusters of one taxtel (or of one row of taxtels) stable.

    Args:
        k_start: ``(n_palette, 2)`` starting wave vectors, cycles/mm.
        k_member, c_member, position, cluster: the matched member components: wave vector,
            amplitude, taxtel centre (mm) and palette entry.

    Returns:
        ``(n_palette, 2)`` wave vectors, cycles/mm.
    """
    k_cluster = np.array(k_start, dtype=np.float64)
    if cluster.size == 0:
        return k_cluster

    def total(values: np.ndarray) -> np.ndarray:
        return np.bincount(cluster, weights=values, minlength=n_palette)

    weight = np.abs(c_member)
    weight_sum = total(weight)
    safe = np.where(weight_sum > 0, weight_sum, 1.0)
    mean_x = total(weight * position[:, 0]) / safe
    mean_y = total(weight * position[:, 1]) / safe
    dx, dy = position[:, 0] - mean_x[cluster], position[:, 1] - mean_y[cluster]
    prior = 1e-3 * total(weight * (dx * dx + dy * dy)) + 1e-12
    sxx, syy, sxy = (
        total(weight * dx * dx) + prior,
        total(weight * dy * dy) + prior,
        total(weight * dx * dy),
    )
    det = sxx * syy - sxy * sxy
    for _ in range(iterations):
        shift = np.einsum("nd,nd->n", k_member - k_cluster[cluster], position)
        local = c_member * np.exp(2j * np.pi * shift)
        mean = total(local.real) + 1j * total(local.imag)
        residual = np.angle(local * np.conj(mean[cluster])) / (2.0 * np.pi)  # cycles
        sxr, syr = total(weight * dx * residual), total(weight * dy * residual)
        # A residual growing along x means the common k is too small there.
        k_cluster[:, 0] += (syy * sxr - sxy * syr) / det
        k_cluster[:, 1] += (sxx * syr - sxy * sxr) / det
    return k_cluster
