"""Verify a fitted profile on the device: play held-out textures without and with it, and
measure the rendered friction each time (spec/calibration.md K18).

Both plays go through the same connection, one after the other: the first with the device's
own profile, the second with the fitted profile uploaded (UPLOAD_END COMMIT_PROFILE); the
device is left with its own profile. The rendering error of each is measured from the recorded
lateral force (:func:`hcard.calibration.rendering.rendering_error`), never from a model of the
commands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from hcard.calibration.measurement import Measurement
from hcard.calibration.rendering import RenderingError, rendering_error
from hcard.device.open import open_device
from hcard.device.play import play
from hcard.device.play_result import PlayResult
from hcard.device.recording import recording
from hcard.track import FingerTrack
from hcard.v1 import card_pb2 as pb


@dataclass(frozen=True)
class Verification:
    """The rendered friction error without and with a profile.

    Attributes:
        before: with the device's own profile.
        after: with the fitted profile.
        recordings: the two recordings (before, after), measurement format.
        results: the two play results (before, after).
        uri: the device.
    """

    before: RenderingError
    after: RenderingError
    recordings: tuple[Measurement, Measurement]
    results: tuple[PlayResult, PlayResult]
    uri: str

    @property
    def ratio(self) -> float:
        """How many times the profile cut the patch RMS error (before / after)."""
        return self.before.patch_rms / self.after.patch_rms if self.after.patch_rms else math.inf

    def text(self) -> str:
        """One line for people."""
        return (f"{self.before.patch_rms:.4f} with the device's own profile, "
                f"{self.after.patch_rms:.4f} with the fitted profile ({self.ratio:.2f}x; "
                f"relative friction, RMS over {self.after.patches} held-out texture patches)")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures (``text`` included)."""
        return {
            "uri": self.uri,
            "before": self.before.to_dict(),
            "after": self.after.to_dict(),
            "ratio": self.ratio if math.isfinite(self.ratio) else None,
            "text": self.text(),
        }


def verify(uri: str, card: pb.Card, track: FingerTrack, profile: bytes, *,
           timeout_s: float = 1.0, track_path: str | None = None,
           card_path: str | None = None) -> Verification:
    """Play ``card`` along ``track`` on ``uri`` with the device's own profile, then with
    ``profile`` (the bytes of a profile file), and measure both renderings.

    Raises:
        DeviceError: the device is missing, refuses the card or the profile.
        MeasurementError: a recording has nothing to measure (no plain or modulated patch).
    """
    with open_device(uri, timeout_s=timeout_s) as driver:
        before = play(driver, card, track, profile=None)
        after = play(driver, card, track, profile=profile)
        driver.use_device_profile()
    recordings = (
        recording(before, track_path=track_path, card_path=card_path),
        recording(after, track_path=track_path, card_path=card_path),
    )
    return Verification(rendering_error(recordings[0]), rendering_error(recordings[1]),
                        recordings, (before, after), str(uri))
