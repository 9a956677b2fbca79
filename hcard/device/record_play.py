"""Play a card along a track on a device and write the recording: what ``hcard play`` does, and
what the separating experiment of a calibration run does (spec/calibration.md K34)."""

from __future__ import annotations

import contextlib
from pathlib import Path

from hcard.device.open import open_device
from hcard.device.play import check_play_length, play
from hcard.device.play_result import PlayResult
from hcard.device.priority import real_time_host
from hcard.device.recording import write_recording
from hcard.errors import HcardError
from hcard.file_errors import write_failure
from hcard.track import FingerTrack
from hcard.v1 import card_pb2 as pb


def play_and_record(uri: str, card: pb.Card, track: FingerTrack, output: Path, *,
                    card_path: str, track_path: str, timeout_s: float = 1.0,
                    profile: bytes | None = None,
                    ambient_pressure_pa: float | None = None) -> PlayResult:
    """Play ``card`` along ``track`` on the device at ``uri`` (``profile``: the bytes of a
    device profile to render with; None: the device's own), a whole session at real-time
    priority on a real-time device, and write the recording with its sidecar to ``output``
    (naming ``card_path`` and ``track_path``, and the air pressure the lab measured around
    the plate, ``ambient_pressure_pa`` in Pa, when given).

    Raises:
        PlayTooLong: the track is longer than a play may be (nothing is sent).
        DeviceError: the device refused, was busy or lost the session (nothing is written).
        HcardError: the recording cannot be written.
    """
    check_play_length(track)
    with open_device(uri, timeout_s=timeout_s) as driver, \
            real_time_host() if driver.realtime else contextlib.nullcontext():
        result = play(driver, card, track, profile=profile, whole_session=True)
    try:
        write_recording(result, output, track_path=track_path, card_path=card_path,
                        ambient_pressure_pa=ambient_pressure_pa)
    except ValueError as exc:
        raise HcardError(f"{output}: {exc}") from None
    except OSError as exc:
        raise HcardError(write_failure(output, exc)) from None
    return result
