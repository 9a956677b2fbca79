"""What ``device.host-driver`` observes of a host operation: whether it returned, raised the
host library's error, or crashed, and which numbers its error message names (spec/conformance.md
4.10); and the short card and stroke its cases play."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hcard import build
from hcard.device.protocol import DeviceInfo
from hcard.errors import HcardError
from hcard.track import FingerTrack, straight_stroke
from hcard.v1 import card_pb2 as pb
from hcard_conformance.device_checks.common import STROKE_SPEED_MM_S

PLAY_S = 0.2
"""Length of the stroke a case plays, s (ten 50 Hz touch samples; 200 STATE reports)."""
MIN_REPORTS = int(PLAY_S * 1000 * 0.9)
"""Fewest STATE reports a play of a case must return: 90 % of the 1 kHz reports of its
stroke."""


@dataclass(frozen=True)
class Outcome:
    """What one host operation did.

    Attributes:
        what: the operation, for a detail line (``play``, ``start()``...).
        value: what it returned (None when it raised).
        error: the exception it raised (None when it returned).
    """

    what: str
    value: Any = None
    error: Exception | None = None

    @property
    def crashed(self) -> bool:
        """It raised something other than the host library's error
        (:class:`~hcard.errors.HcardError`: a driver reports what it cannot do with it; any
        other exception is the driver breaking, PE4's crash)."""
        return self.error is not None and not isinstance(self.error, HcardError)

    def message(self, uri: object) -> str:
        """The error's message with the URI (whose digits name nothing) left out; "" when it
        returned."""
        if self.error is None:
            return ""
        return " ".join(str(self.error).replace(str(uri), "").split())

    def text(self) -> str:
        """``play raised SessionBusy: ...`` or ``play returned``, for a detail line."""
        if self.error is None:
            return f"{self.what} returned"
        message = " ".join(str(self.error).split())
        return f"{self.what} raised {type(self.error).__name__}: {message}"


def attempt(what: str, operation: Callable[[], Any]) -> Outcome:
    """Run one host operation and keep what it did (an interrupt still stops the run)."""
    try:
        return Outcome(what, operation())
    except Exception as exc:  # what the driver raises is the measurement
        return Outcome(what, error=exc)


def names_number(message: str, number: int | str) -> bool:
    """``message`` names ``number`` as a number of its own (not inside another number, a
    version or an identifier such as PV2): ``6`` in "session 6 of", not in "0.6" or "16"."""
    return re.search(rf"(?<![\w.]){re.escape(str(number))}(?![\w]|\.\d)", message) is not None


def names_major(message: str, major: int) -> bool:
    """``message`` names protocol major version ``major``: ``1``, ``1.x`` or ``1.4``."""
    return re.search(rf"(?<![\w.]){major}(?:\.(?:\d+|x))?(?![\w.]|\.\d)", message) is not None


def names_any(message: str, words: tuple[str, ...]) -> bool:
    """``message`` names one of ``words`` (report names as the spec writes them, report IDs in
    hex, ignoring case, or numbers: :func:`names_number`)."""
    for word in words:
        if word.isdigit():
            if names_number(message, word):
                return True
        elif word.lower().startswith("0x"):
            if re.search(rf"(?<![\w]){re.escape(word)}(?![\w])", message, re.I):
                return True
        elif re.search(rf"(?<![\w]){re.escape(word)}", message):
            return True
    return False


def stroke_card(info: DeviceInfo) -> pb.Card:
    """A card over the whole surface of ``info``: friction 1 on the left half, 0.5 on the
    right."""
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    return build.card(width, height, taxtel_mm=(width / 2, height), textures=[
        build.texture(1.0, channel="uv"), build.texture(0.5, channel="uv")], texture_index=[0, 1])


def stroke_track(info: DeviceInfo) -> FingerTrack:
    """A :data:`PLAY_S` stroke across the middle of the surface of ``info`` along +x."""
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    return straight_stroke((width / 2 - STROKE_SPEED_MM_S * PLAY_S / 2, height / 2),
                           (STROKE_SPEED_MM_S, 0.0), PLAY_S)
