"""The finger's own history, frame by frame: how long it has touched (occlusion) and how many
strokes it has made since it last rested (skin recovery), with its state carried across
simulation steps (vectorised per step).

- Occlusion time: the time in contact since the finger arrived, lifts excluded (the dynamic
  occlusion time of Fig. 1.11b): it pauses while the finger is lifted and does not restart at
  a touch-down. At frame ``k`` it is ``dt`` times the frames in contact up to and including
  ``k``.
- Strokes since rest ``k``: 0 for the first stroke after a rest; a new stroke starts where the
  finger reverses its direction along x while in contact (the sign of its x motion between two
  frames in contact changes; frames without motion carry the previous sign) and at a touch-down
  after a lift shorter than :data:`REST_S`; a lift of at least :data:`REST_S` rests the finger
  (the next touch-down is stroke 0). The finger has rested before its first touch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hcard_device.sim.finger import FingerTruth

REST_S = 0.5
"""A lift at least this long rests the finger, s (the stroke count restarts at 0)."""


@dataclass(frozen=True)
class FingerHistory:
    """The finger's history at the frames of one step.

    Attributes:
        occlusion_time_s: time in contact up to each frame, lifts excluded, s.
        stroke: strokes since the finger last rested (meaningful in contact).
        touchdown: the frame is the first of a contact.
    """

    occlusion_time_s: np.ndarray
    stroke: np.ndarray
    touchdown: np.ndarray


class FingerClock:
    """The finger's history (module documentation), step after step.

    Args:
        frame_s: frame interval, s.
    """

    def __init__(self, frame_s: float) -> None:
        self.frame_s = frame_s
        self._rest_frames = round(REST_S / frame_s)
        self.reset()

    def reset(self) -> None:
        """A new finger: never touched, rested."""
        self._frame = 0  # frames seen
        self._contact_frames = 0  # of them in contact
        self._last_contact = -(1 << 62)  # frame of the last contact (long ago: rested)
        self._touching = False  # the last frame was in contact
        self._x = 0.0  # its x, mm
        self._sign = 0  # direction of the current stroke along x (0: none yet)
        self._stroke = 0

    def advance(self, truth: FingerTruth) -> FingerHistory:
        """The history at the frames of ``truth`` (the next ones after the previous call's)."""
        contact = truth.contact
        n = contact.shape[0]
        index = self._frame + np.arange(n)
        counted = self._contact_frames + np.cumsum(contact)
        occlusion = counted * self.frame_s
        before = np.concatenate(([self._touching], contact[:-1]))
        touchdown = contact & ~before
        # the last frame in contact before each frame
        last = np.where(contact, index, -(1 << 62))
        np.maximum.accumulate(last, out=last)
        previous = np.concatenate(([self._last_contact], last[:-1]))
        np.maximum(previous, self._last_contact, out=previous)
        rest = touchdown & (index - previous >= self._rest_frames)
        # direction along x between two frames in contact, carried over still frames; a
        # touch-down clears it (the stroke it starts is counted as a touch-down)
        x = truth.x_mm
        step = np.sign(np.diff(x, prepend=self._x)) * (contact & before)
        marks = (step != 0) | touchdown
        where = np.where(marks, np.arange(n), -1)
        np.maximum.accumulate(where, out=where)
        sign = np.where(where >= 0, step[np.maximum(where, 0)], self._sign)
        prior = np.concatenate(([self._sign], sign[:-1]))
        reversal = (step != 0) & (prior != 0) & (step != prior)
        new = reversal | (touchdown & ~rest)
        counts = np.cumsum(new)
        rests = np.where(rest, np.arange(n), -1)
        np.maximum.accumulate(rests, out=rests)
        stroke = np.where(rests >= 0, counts - counts[np.maximum(rests, 0)],
                          self._stroke + counts)
        if n:
            self._frame += n
            self._contact_frames = int(counted[-1])
            self._last_contact = int(max(last[-1], self._last_contact))
            self._touching = bool(contact[-1])
            self._x = float(x[-1])
            self._sign = int(sign[-1])
            self._stroke = int(stroke[-1])
        return FingerHistory(occlusion, stroke.astype(np.float64), touchdown)
