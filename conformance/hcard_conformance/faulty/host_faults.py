"""The faulty device's driver faults: rendering on the host done wrong
(:class:`FaultyRendering`, a :class:`~hcard.device.host_rendering.HostRendering`), each
with a strength (:class:`RenderingFaults`; all zero: the host library's own rendering).

- the card as the driver reads it (:func:`misread`): every component's phase, frequency or
  amplitude off (rules R9, R10), every target's distance from neutral friction scaled
  (R11), or position-locked textures locked to the odometer (R8);
- the rendering's settings: the band limit raised (R10: the fade of components near it moves
  up with it);
- the finger as the driver takes it: its position offset along x (R7), or each sample applied
  late.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from hcard.device.host_rendering import HostRendering
from hcard.physics.profile import DeviceProfile
from hcard.render import RenderOptions
from hcard.render.compiled import velocity_locked
from hcard.v1 import card_pb2 as pb


@dataclass(frozen=True)
class RenderingFaults:
    """The driver faults of one rendering (each 0 without the fault; see :mod:`.faults`).

    Attributes:
        touch_offset_mm: added to every finger x, mm.
        touch_lag_s: each finger sample is applied this long after it arrives, s.
        phase_offset_rad: added to every component's phase, rad.
        frequency_error: relative error of every component frequency (signed).
        amplitude_error: relative error of every component amplitude (signed).
        depth_error: relative error of every texture's distance from neutral friction, its
            baseline's and its components' (signed).
        velocity_locked_below_mm: a position-locked texture (LOCKING_POSITION, or AUTO whose
            components resolve to position, R8) whose shortest spatial period is below this is
            rendered velocity-locked, mm (0: none).
        band_limit_excess_hz: added to the band limit the rendering fades components at, Hz.
    """

    touch_offset_mm: float = 0.0
    touch_lag_s: float = 0.0
    phase_offset_rad: float = 0.0
    frequency_error: float = 0.0
    amplitude_error: float = 0.0
    depth_error: float = 0.0
    velocity_locked_below_mm: float = 0.0
    band_limit_excess_hz: float = 0.0


def _misread_component(component: pb.Component, faults: RenderingFaults) -> None:
    """Apply the component faults to ``component`` in place."""
    component.phase = math.remainder(component.phase + faults.phase_offset_rad, 2.0 * math.pi)
    component.frequency *= 1.0 + faults.frequency_error
    component.amplitude *= (1.0 + faults.amplitude_error) * (1.0 + faults.depth_error)


def _position_periods_mm(texture: pb.Texture, options: RenderOptions) -> list[float]:
    """Spatial periods (mm) of the components of ``texture`` that are position-locked (R8)."""
    return [1.0 / c.frequency for c in texture.components
            if c.domain == pb.DOMAIN_SPATIAL and c.frequency > 0
            and not velocity_locked(c, texture.locking, options)]


def misread(card: pb.Card, faults: RenderingFaults, options: RenderOptions) -> pb.Card:
    """A copy of ``card`` as a driver with ``faults`` reads it (rendered with ``options``)."""
    read = pb.Card()
    read.CopyFrom(card)
    for texture in read.textures:
        periods = _position_periods_mm(texture, options)
        if periods and min(periods) < faults.velocity_locked_below_mm:
            texture.locking = pb.LOCKING_VELOCITY
        texture.baseline = 1.0 + (texture.baseline - 1.0) * (1.0 + faults.depth_error)
        for component in texture.components:
            _misread_component(component, faults)
    return read


class FaultyRendering(HostRendering):
    """:class:`HostRendering` with the driver faults ``faults``.

    Args:
        profile: the device's physics profile.
        frame_rate_hz: the device's frame rate, Hz.
        faults: the rendering's faults.
    """

    def __init__(self, profile: DeviceProfile, frame_rate_hz: float,
                 faults: RenderingFaults) -> None:
        super().__init__(profile, frame_rate_hz)
        self.faults = faults
        self.options = replace(self.options, band_limit_hz=self.options.band_limit_hz
                               + faults.band_limit_excess_hz)

    def load(self, card: pb.Card) -> None:
        """Render ``card`` as misread (:func:`misread`) from the next frame on."""
        super().load(misread(card, self.faults, self.options))

    def finger(self, t_s: float, arrived_s: float, x_mm: float, y_mm: float,
               normal_force_n: float, contact: bool, host_time_us: int) -> None:
        """A finger sample, offset along x and applied late as the faults say."""
        super().finger(t_s, arrived_s + self.faults.touch_lag_s,
                       x_mm + self.faults.touch_offset_mm, y_mm, normal_force_n, contact,
                       host_time_us)
