"""A card's clip report (:mod:`hcard.physics.card_clipping`) as the CLIP_REPORT feature report
(spec/device-protocol.md): one clipped item at a time, selected by index."""

from __future__ import annotations

from hcard.device.protocol import FORCE_UNIT_N, FRICTION_SCALE, ClipReason, ClipReport
from hcard.device.protocol.upload import detail_text
from hcard.physics.card_clipping import ClipItem
from hcard.physics.card_clipping import ClipReport as CardClipping
from hcard.quantities import MM_PER_M

_U16 = 0xFFFF
_NAME_BYTES = 41


def clip_reason(item: ClipItem) -> int:
    """CLIP_REPORT reason (:class:`ClipReason`) of one clipped item."""
    if item.reason.startswith("no UV"):
        return ClipReason.NO_UV
    if item.reason.startswith("no EV"):
        return ClipReason.NO_EV
    if item.channel == "uv":
        return ClipReason.AMPLITUDE
    if item.channel == "ev":
        return ClipReason.VOLTAGE
    return ClipReason.OTHER


def _clamp(value: float, low: int, high: int) -> int:
    return max(low, min(high, round(value)))


def wire_clip_report(report: CardClipping | None, generation: int, index: int) -> ClipReport:
    """CLIP_REPORT of the active card ``report`` (None: no card) of card ``generation``,
    describing item ``index`` (the last item when past it)."""
    items: tuple[ClipItem, ...] = report.items if report is not None else ()
    flags = 0
    for item in items:
        flags |= 1 << min(clip_reason(item), 15)
    speed = report.reference_speed_m_s if report is not None else 0.0
    force = report.reference_force_n if report is not None else 0.0
    common = {
        "card_generation": generation,
        "item_count": min(len(items), 512),
        "clipped_textures": len({item.texture for item in items}),
        "flags": flags,
        "reference_speed_mm_s": _clamp(speed * MM_PER_M, 0, _U16),
        "reference_force_mn": _clamp(force / FORCE_UNIT_N, 0, _U16),
    }
    if not items:
        return ClipReport(**common, item_index=ClipReport.NO_ITEM, texture=-1, channel=0,
                          reason=0, target_x1e4=0, achievable_x1e4=0, texture_name="")
    index = min(index, len(items) - 1)
    item = items[index]
    return ClipReport(
        **common,
        item_index=index,
        texture=item.texture,
        channel=1 if item.channel == "uv" else 2,
        reason=clip_reason(item),
        target_x1e4=_clamp(item.target * FRICTION_SCALE, 0, 4 * FRICTION_SCALE),
        achievable_x1e4=_clamp(item.achievable * FRICTION_SCALE, 0, 4 * FRICTION_SCALE),
        texture_name=detail_text(item.name)[0][:_NAME_BYTES],
    )
