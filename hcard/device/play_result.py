"""What a play session saw (:class:`PlayResult`), shared by :mod:`.play` that fills it,
:mod:`.recording` that writes it as a recording and :mod:`.play_summary` that describes it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hcard.device.base import UploadOutcome
from hcard.device.protocol import Counters, DeviceInfo, FaultBits, Limits
from hcard.device.state_log import StateLog
from hcard.quantities import US_PER_S
from hcard.track import FingerTrack

HOST_TIME_MODULO = 1 << 32
"""FINGER.host_time_us wraps at 2**32 us."""


@dataclass(frozen=True)
class PlayResult:
    """What :func:`play` saw.

    Attributes:
        states: every STATE report, in arrival order, packed (:class:`StateLog`).
        duration_s: driver clock time from START to the end of collection, s.
        upload: the upload outcome (status, clip report).
        info: DEVICE_INFO.
        counters: COUNTERS read at the end.
        reports_lost: reports missed (sequence gaps), host side.
        malformed: input reports that could not be decoded.
        track: the finger track played.
        card_bytes: the card as uploaded (binary form).
        card_title: the card's title.
        limits: the device's limits in force during the session, read back at its end.
        limits_at_start: those read back when the session began, when they differ from
            :attr:`limits` (the limits changed during the recording); None otherwise.
        profile: the profile record of the recording's sidecar (``source``, ``name``,
            ``sha256``, ``content``; spec/measurement-format.md rule MF9).
        uri: the device URI.
        started: when the session started, ISO 8601 UTC.
        host_us: the host time sent with each track sample (FINGER.host_time_us, u32 us):
            the session's start on the driver's clock plus the sample's track time, so an
            echo names one sample of this session and never one of an earlier session.
    """

    states: StateLog
    duration_s: float
    upload: UploadOutcome
    info: DeviceInfo
    counters: Counters
    reports_lost: int
    malformed: int
    track: FingerTrack
    card_bytes: bytes = b""
    card_title: str = ""
    limits: Limits = field(default_factory=lambda: Limits(0, 0, 0))
    profile: dict[str, Any] = field(default_factory=dict)
    uri: str = ""
    started: str = ""
    host_us: np.ndarray | None = None
    limits_at_start: Limits | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.states, StateLog):  # reports given as a list of State
            object.__setattr__(self, "states", StateLog(self.states))

    def sent_host_us(self) -> np.ndarray:
        """:attr:`host_us`, or the track's own times for a result built without them."""
        if self.host_us is not None:
            return self.host_us
        return np.rint(self.track.t * US_PER_S).astype(np.int64) % HOST_TIME_MODULO

    @property
    def faults(self) -> FaultBits:
        """Every fault seen in the reports or latched by the device."""
        return FaultBits(self.counters.latched_faults | self.states.faults_seen)
