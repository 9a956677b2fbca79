"""Texture palette: merge similar taxtel textures, as an indexed-colour image merges colours.

The distance between two textures is the RMS difference of their friction fields:

    d^2 = (b1 - b2)^2 + 1/2 sum_unmatched A^2 + 1/2 sum_matched |A1 e^{i phi1} - A2 e^{i phi2}|^2

where two components match when their wave vectors differ by less than one frequency bin
(``1 / taxtel`` cycles/mm); a wave vector ``k`` also matches ``-k`` with the conjugate amplitude
(the same grating written the other way round). Written with the energies ``E = sum A^2`` this
is ``(b1-b2)^2 + E1/2 + E2/2 - sum_matched Re(C1 conj C2)``, which is how it is computed.

Clustering, all vectorised over taxtels (loops run over leaders, palette entries and component
slots, never over taxtels):

1. leader clustering, farthest first: the first taxtel leads; the taxtel farthest from every
   leader becomes the next leader while it is farther than the tolerance, so every taxtel ends
   within the tolerance of its leader (at most :func:`leader_cap` leaders);
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


@dataclass(frozen=True)
class _Flat:
    """Textures as one flat list of components (owner, wave vector, amplitude), so that the
    distance from one texture to all of them costs O(components), not O(textures * slots)."""

    baseline: np.ndarray
    energy: np.ndarray
    owner: np.ndarray
    kx: np.ndarray
    ky: np.ndarray
    re: np.ndarray
    im: np.ndarray

    @classmethod
    def of(cls, textures: Textures) -> _Flat:
        owner, slot = np.nonzero(textures.valid)
        coef = textures.coef[owner, slot]
        k = textures.k[owner, slot]
        return cls(
            baseline=textures.baseline,
            energy=textures.energy,
            owner=owner,
            kx=k[:, 0],
            ky=k[:, 1],
            re=coef.real,
            im=coef.imag,
        )


def distances_from(one: Textures, i: int, many: Textures, bin_width: float) -> np.ndarray:
    """RMS friction difference between texture ``i`` of ``one`` and every texture of ``many``.

    Args:
        one, i: the reference texture.
        many: textures to compare with (``n`` of them).
        bin_width: matching distance of wave vectors, cycles/mm.

    Returns:
        ``(n,)`` distances in relative friction units.
    """
    return _distances(one, i, _Flat.of(many), bin_width)


def _distances(one: Textures, i: int, many: _Flat, bin_width: float) -> np.ndarray:
    own = one.valid[i]
    k0, c0 = one.k[i][own], one.coef[i][own]
    d2 = (one.baseline[i] - many.baseline) ** 2 + 0.5 * (np.sum(np.abs(c0) ** 2) + many.energy)
    if c0.size and many.owner.size:
        limit = bin_width * bin_width
        kx, ky = k0[:, 0:1], k0[:, 1:2]  # (q, 1) against (m,): all pairs at once
        direct = (many.kx - kx) ** 2 + (many.ky - ky) ** 2 < limit
        mirror = ((many.kx + kx) ** 2 + (many.ky + ky) ** 2 < limit) & ~direct
        # Re(c conj C) for a direct match, Re(c C) for a mirrored one.
        same = c0.real[:, None] * many.re
        cross = c0.imag[:, None] * many.im
        overlap = np.where(direct, same + cross, np.where(mirror, same - cross, 0.0))
        d2 -= np.bincount(many.owner, weights=overlap.sum(axis=0), minlength=many.baseline.size)
    return np.sqrt(np.maximum(d2, 0.0))


def leader_cap(max_textures: int) -> int:
    """Most leaders the first stage may create before merging: ``2 * max_textures + 64``."""
    return 2 * max_textures + 64


def build_palette(
    textures: Textures,
    centres: np.ndarray,
    *,
    bin_width: float,
    tolerance: float,
    max_textures: int,
    min_amplitude: float,
) -> Palette:
    """Merge per-taxtel ``textures`` into a palette of at most ``max_textures`` entries.

    Args:
        textures: one texture per taxtel.
        centres: ``(n, 2)`` taxtel centres, millimetres (to compare phases locally).
        bin_width: frequency resolution, cycles/mm (``1 / taxtel_mm``).
        tolerance: leader-clustering radius, relative friction (RMS).
        max_textures: palette size limit.
        min_amplitude: components of the merged textures weaker than this are dropped.
    """
    if max_textures < 1:
        raise ValueError(f"max_textures must be at least 1, got {max_textures}")
    textures = align_wave_vectors(textures.trimmed(), centres, bin_width)
    flat = _Flat.of(textures)
    leaders, assign = _leaders(textures, flat, bin_width, tolerance, leader_cap(max_textures))
    found = len(leaders)
    if found > max_textures:
        heads = _agglomerate(textures, leaders, assign, bin_width, max_textures)
        assign = _nearest(textures, flat, heads, bin_width)
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
    merged = _centroids(textures, centres, representatives, assign, bin_width, min_amplitude)
    return Palette(merged, assign, found)


def align_wave_vectors(
    textures: Textures, centres: np.ndarray, bin_width: float, cell: float = 0.1
) -> Textures:
    """Give components of (nearly) the same wave vector in different taxtels one common value.

    Each taxtel measures its gratings' wave vectors with a small error; extrapolating its phase
    to the surface origin multiplies that error by the distance, so identical gratings far from
    the origin would look different. Components whose wave vectors fall in the same cell of
    ``cell * bin_width`` cycles/mm get the amplitude-weighted mean wave vector of the cell, and
    their phases are re-referenced so that they do not change at their taxtel's centre.
    """
    valid = textures.valid
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
    return Textures(textures.baseline, new_k, new_coef, valid)


def _leaders(
    textures: Textures, flat: _Flat, bin_width: float, tolerance: float, cap: int
) -> tuple[list[int], np.ndarray]:
    """Farthest-first leader clustering; returns leader taxtels and each taxtel's leader slot."""
    leaders = [0]
    best = _distances(textures, 0, flat, bin_width)
    assign = np.zeros(best.size, dtype=np.int64)
    while len(leaders) < cap:
        j = int(np.argmax(best))
        if best[j] <= tolerance:
            break
        distance = _distances(textures, j, flat, bin_width)
        closer = distance < best
        best[closer] = distance[closer]
        assign[closer] = len(leaders)
        leaders.append(j)
    return leaders, assign


def _agglomerate(
    textures: Textures,
    leaders: list[int],
    assign: np.ndarray,
    bin_width: float,
    max_textures: int,
) -> list[int]:
    """Merge the closest pair of leader clusters until ``max_textures`` remain."""
    heads = textures.take(np.asarray(leaders))
    flat = _Flat.of(heads)
    count = len(leaders)
    distance = np.stack([_distances(heads, i, flat, bin_width) for i in range(count)])
    np.fill_diagonal(distance, np.inf)
    weight = np.bincount(assign, minlength=count).astype(np.float64)
    alive = count
    while alive > max_textures:
        i, j = np.unravel_index(int(np.argmin(distance)), distance.shape)
        keep, drop = (i, j) if weight[i] >= weight[j] else (j, i)
        weight[keep] += weight[drop]
        distance[drop, :] = np.inf
        distance[:, drop] = np.inf
        weight[drop] = 0.0
        alive -= 1
    return [leaders[i] for i in np.nonzero(weight > 0)[0]]


def _nearest(
    textures: Textures, flat: _Flat, representatives: list[int], bin_width: float
) -> np.ndarray:
    """Index (into ``representatives``) of the nearest representative of every taxtel."""
    distance = np.stack([_distances(textures, r, flat, bin_width) for r in representatives])
    return np.argmin(distance, axis=0)


def _centroids(
    textures: Textures,
    centres: np.ndarray,
    representatives: np.ndarray,
    assign: np.ndarray,
    bin_width: float,
    min_amplitude: float,
) -> Textures:
    """Palette textures: each cluster's mean baseline and mean matched components."""
    n_palette = representatives.size
    members = np.bincount(assign, minlength=n_palette).astype(np.float64)
    baseline = np.bincount(assign, weights=textures.baseline, minlength=n_palette) / members
    heads = textures.take(representatives).trimmed()
    k = heads.k.copy()
    coef = np.zeros(heads.coef.shape, dtype=np.complex128)
    owner, slot = np.nonzero(textures.valid)  # every component of every taxtel, by taxtel
    comp_k, comp_c = textures.k[owner, slot], textures.coef[owner, slot]
    cluster = assign[owner]
    for j in range(heads.valid.shape[1]):
        chosen, k_member, c_member = _match(
            owner, comp_k, comp_c, heads.k[cluster, j], heads.valid[cluster, j], bin_width
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
    bin_width: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each taxtel, its component nearest to its reference wave vector within a bin.

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
    candidate = np.nonzero(active & (distance < bin_width))[0]
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
