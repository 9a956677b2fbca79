"""What a card asks that a device profile cannot render: the clip report of a card on a profile
(the reference firmware's ``load_card`` and the host-rendering frame driver both make it).

For each texture the grid uses, the extreme targets follow from its baseline and component
amplitudes per channel group (the renderer's split, spec rule R11, Eq. 4.1)::

    uv_min = clip(1 + b_uv - A_uv, 0, 1) * min(clip(1 + b_bip - A_bip, 0, 4), 1)
    ev_max = min(clip(1 + b_ev + A_ev, 1, 4) * max(clip(1 + b_bip + A_bip, 0, 4), 1), 4)

(``b`` the baseline deviation and ``A`` the summed amplitudes of each group; reached when the
components line up, so the report is conservative). They are checked at a reference finger state
(:data:`REFERENCE_SPEED_M_S`, :data:`REFERENCE_FORCE_N`) against what the device profile can
render at its limits: the UV target needs an amplitude that grows with the finger speed
(velocity compensation, Eq. 2.30), the EV target a voltage that grows with the normal force
(``F_e = (ev - 1) Fn``, Eq. 4.1). A channel the device lacks clips every target off neutral.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcard.physics.profile import DeviceProfile
from hcard.quantities import MM_PER_M, UM_PER_M
from hcard.render.compiled import compile_texture
from hcard.render.options import RenderOptions
from hcard.render.synthesis import channel_targets
from hcard.v1 import card_pb2 as pb

REFERENCE_SPEED_M_S = 0.120
"""Finger speed of the report, m/s: the top of the 10-120 mm/s exploration range (section
1.4.2.3, [28]); the UV amplitude needed grows with speed."""
REFERENCE_FORCE_N = 0.5
"""Normal force of the report, N (the track default; the EV force needed grows with it)."""
_TOLERANCE = 1e-9


@dataclass(frozen=True)
class ClipItem:
    """One texture target the device cannot render.

    Attributes:
        texture: palette index.
        name: texture name.
        channel: ``"uv"`` or ``"ev"``.
        reason: what limits it, in words.
        target: the extreme relative friction the texture asks for.
        achievable: the closest the device renders at the reference state.
    """

    texture: int
    name: str
    channel: str
    reason: str
    target: float
    achievable: float

    def __str__(self) -> str:
        label = f"texture {self.texture}" + (f" ({self.name})" if self.name else "")
        return (
            f"{label}, {self.channel.upper()}: asks {self.target:.3f}, renders "
            f"{self.achievable:.3f} ({self.reason})"
        )


@dataclass(frozen=True)
class ClipReport:
    """What a loaded card asks beyond the device (empty: it renders as written).

    Attributes:
        items: one entry per texture and channel that clips.
        reference_speed_m_s: finger speed the targets were checked at, m/s.
        reference_force_n: normal force they were checked at, N.
    """

    items: tuple[ClipItem, ...] = ()
    reference_speed_m_s: float = REFERENCE_SPEED_M_S
    reference_force_n: float = REFERENCE_FORCE_N

    @property
    def clipped(self) -> bool:
        """True when some target cannot be rendered."""
        return bool(self.items)

    def summary(self) -> str:
        """One line per item, or a line saying nothing clips."""
        if not self.items:
            return "the device renders every texture of the card"
        head = (
            f"at {self.reference_speed_m_s * MM_PER_M:g} mm/s and {self.reference_force_n:g} N "
            "the device cannot render:"
        )
        return "\n".join([head, *(f"  {item}" for item in self.items)])

    def __str__(self) -> str:
        return self.summary()


def texture_extremes(texture: pb.Texture) -> tuple[float, float]:
    """``(uv_min, ev_max)`` the texture can ask for (module formula): the renderer's compiled
    texture (channel group of each component, baseline deviation of the texture's group) and
    its R11 split, with every component at its trough for ``uv_min`` and at its crest for
    ``ev_max``."""
    compiled = compile_texture(texture, RenderOptions())
    amplitude = np.zeros(3)  # summed in component order, as the kernel's sum would be
    np.add.at(amplitude, compiled.group_matrix.argmax(axis=1), np.abs(compiled.amplitude))
    uv, _ = channel_targets(compiled.baseline_deviation - amplitude)
    _, ev = channel_targets(compiled.baseline_deviation + amplitude)
    return float(uv[0]), float(ev[0])


@dataclass(frozen=True)
class TextureExtremes:
    """What one texture of a card asks at its extremes (:func:`texture_extremes`).

    Attributes:
        texture: palette index.
        name: texture name.
        uv_min: lowest relative friction it asks of the UV channel group.
        ev_max: highest relative friction it asks of the EV channel group.
    """

    texture: int
    name: str
    uv_min: float
    ev_max: float


def card_extremes(card: pb.Card) -> tuple[TextureExtremes, ...]:
    """The extremes of every texture the grid of ``card`` uses, in palette order: the part of
    the clip report that depends on the card only (a texture compiled per entry: 0.15 s for
    the largest valid card, so computed once per card, outside the device's lock)."""
    used = sorted({int(i) for i in card.grid.texture_index if 0 <= i < len(card.textures)})
    extremes = []
    for index in used:
        texture = card.textures[index]
        uv_min, ev_max = texture_extremes(texture)
        extremes.append(TextureExtremes(index, texture.name, uv_min, ev_max))
    return tuple(extremes)


def clip_items(
    extremes: tuple[TextureExtremes, ...],
    profile: DeviceProfile,
    *,
    speed_m_s: float = REFERENCE_SPEED_M_S,
    force_n: float = REFERENCE_FORCE_N,
) -> ClipReport:
    """The clip report of a card's ``extremes`` (:func:`card_extremes`) on the device
    ``profile`` (its limits included): the best each channel renders at the reference state
    is computed once, what a clipped texture would need once per clipped item."""
    items: list[ClipItem] = []
    limits = profile.rendering_limits()
    best_uv: float | None = None
    best_ev: float | None = None
    for entry in extremes:
        index, name, uv_min, ev_max = entry.texture, entry.name, entry.uv_min, entry.ev_max
        if uv_min < 1.0 - _TOLERANCE:
            if profile.uv_model is None or limits.max_amplitude <= 0:
                items.append(ClipItem(index, name, "uv", "no UV channel", uv_min, 1.0))
            else:
                if best_uv is None:
                    best_uv = float(profile.uv_for(limits.max_amplitude, speed_m_s, force_n))
                if best_uv > uv_min + _TOLERANCE:
                    needed = float(
                        profile.amplitude_for(max(uv_min, 1e-6), speed_m_s, force_n)
                    )
                    items.append(ClipItem(
                        index, name, "uv",
                        f"needs {needed * UM_PER_M:.2f} um > max_amplitude "
                        f"{limits.max_amplitude * UM_PER_M:.2f} um",
                        uv_min, best_uv,
                    ))
        if ev_max > 1.0 + _TOLERANCE:
            voltage_limit, limit_name = profile.voltage_limit
            if profile.ev_model is None or voltage_limit <= 0:
                items.append(ClipItem(index, name, "ev", "no EV channel", ev_max, 1.0))
            else:
                if best_ev is None:
                    best_ev = 1.0 + float(profile.force_for(voltage_limit, force_n)) / force_n
                if best_ev < ev_max - _TOLERANCE:
                    needed = float(profile.voltage_for((ev_max - 1.0) * force_n, force_n))
                    items.append(ClipItem(
                        index, name, "ev",
                        f"needs {needed:.0f} V > {limit_name} bound {voltage_limit:.0f} V",
                        ev_max, best_ev,
                    ))
    return ClipReport(tuple(items), speed_m_s, force_n)


def clip_report(
    card: pb.Card,
    profile: DeviceProfile,
    *,
    speed_m_s: float = REFERENCE_SPEED_M_S,
    force_n: float = REFERENCE_FORCE_N,
) -> ClipReport:
    """The clip report of ``card`` on the device ``profile`` (its limits included)."""
    return clip_items(card_extremes(card), profile, speed_m_s=speed_m_s, force_n=force_n)
