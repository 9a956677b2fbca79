"""A play session in words: what was played, lost, clipped and faulted, and the rendered
friction error against the card's target (:func:`summary`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from hcard.calibration.measurement import MeasurementError
from hcard.channels import LABEL_OF_VALUE
from hcard.device.play_result import PlayResult
from hcard.device.protocol import FRICTION_SCALE, ClipReport, FaultBits
from hcard.device.recording import force_recording

if TYPE_CHECKING:
    from hcard.calibration.rendering import RenderingError


def clip_text(clip: ClipReport) -> str:
    """One phrase on what the device clips of the card (its first clipped item)."""
    if not clip.item_count:
        return "renders as written (nothing clipped)"
    name = f" '{clip.texture_name}'" if clip.texture_name else ""
    channel = LABEL_OF_VALUE.get(clip.channel, "?")
    return (f"clipped: {clip.item_count} item(s) in {clip.clipped_textures} texture(s), e.g. "
            f"texture {clip.texture}{name} {channel} asks {clip.target_x1e4 / FRICTION_SCALE:.3f},"
            f" gets {clip.achievable_x1e4 / FRICTION_SCALE:.3f}")


def result_rendering_error(result: PlayResult) -> RenderingError | str:
    """The rendered friction error of ``result``, or why there is none (a phrase)."""
    # imported here: the rendering error builds on the calibration dataset, whose filters
    # import scipy.signal (1.6 s on a host, over a minute under TCG), which a play never needs
    from hcard.calibration.rendering import rendering_error

    try:
        return rendering_error(force_recording(result))
    except (MeasurementError, ValueError) as exc:
        return str(exc)


def summary(result: PlayResult) -> list[str]:
    """Summary lines: duration, reports received and dropped, faults, profile, friction error."""
    states = result.states
    dropped = result.counters.input_dropped
    faults = result.faults
    fault_names = ", ".join(f.name or str(int(f)) for f in FaultBits if f in faults) or "none"
    profile = result.profile
    name = profile.get("name") or "unnamed"
    if profile.get("source") == "host":
        profile_text = f"{name} (uploaded, sha256 {str(profile.get('sha256'))[:12]})"
    else:
        profile_text = f"the device's own ({name})"
    lines = [
        f"played {result.duration_s:.3f} s: {len(states)} reports received, "
        f"{result.reports_lost} lost in transit (sequence gaps), {dropped} dropped by the device, "
        f"{result.malformed} malformed",
        f"card: {result.upload.bytes_sent} bytes in {result.upload.reports_sent} reports, "
        f"generation {result.upload.status.card_generation}; {clip_text(result.upload.clip)}",
        f"profile: {profile_text}",
        f"faults: {fault_names}",
    ]
    error = result_rendering_error(result)
    if isinstance(error, str):
        lines.append(f"rendered friction error vs target: n/a ({error})")
    else:
        lines.append(f"rendered friction error vs target: {error.text()}")
    return lines

