"""What the suite runs against: the implementation under test and the vectors.

A :class:`Context` names the implementation (``reference``, a device URI such as ``sim://``, or
a negative control of the reference device, ``control:NAME``), opens its driver, and renders a
card along a finger track *the way that implementation does*:

* ``reference`` renders with :func:`hcard.render.render` itself, at the golden frame times;
* a driver plays the track through the device as the host's finger
  (:func:`hcard.device.play.play`) and returns the targets the device *reports* in its
  STATE input reports (``target_uv``, ``target_ev``), one frame per report, on the track's time
  base (see :func:`reported_frames`).

Checks take a Context and never care which of the two they got.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hcard.quantities import US_PER_S
from hcard.render import Frames, RenderOptions
from hcard.render import render as reference_render
from hcard.track import FingerTrack
from hcard.v1 import card_pb2 as pb

if TYPE_CHECKING:
    from hcard.device.base import Driver
    from hcard.device.protocol import DeviceInfo, State

REFERENCE = "reference"
"""Driver name of the reference implementation (hcard.render, no device)."""
DEFAULT_VECTORS = Path(__file__).resolve().parents[2] / "spec" / "vectors"
"""The vectors of this repository (``spec/vectors``)."""

ECHO_MARGIN_PERIODS = 2
"""For a device before protocol 1.3 (no echo age, rule PI3): report periods subtracted from the
echo-based clock offset of :func:`reported_frames` (whose A1 lag search absorbs a later mapping;
the device level, with no lag search, uses one): one because a sample is applied up to a period
before the first report that echoes it, one because such a device places a sample by the
fastest transport it has seen over all sessions (PO2), which may be up to a period faster than
this session's fastest."""

REALTIME_KEY = "driver-realtime"
""":attr:`Context.cache` key: whether the last driver :meth:`Context.render` played through
runs on the wall clock (a host's lateness matters, spec QT3) or in simulated time."""

DEVICE_LAG_KEY = "device-lag"
""":attr:`Context.cache` key: why the device did not keep real time in the last play of
:meth:`Context.render` (REALTIME_LAG, device protocol PI4); empty when it did."""
CLOCK_MISMATCH_KEY = "clock-mismatch"
""":attr:`Context.cache` key: why the last play's reports leave gaps on the host's time line
though none was lost (:func:`~hcard_conformance.realtime.clock_mismatch`), or empty."""

DEVICE_INFO_KEY = "device-info"
""":attr:`Context.cache` key of the device's DEVICE_INFO (:meth:`Context.device_info`)."""

Renderer = Callable[[pb.Card, FingerTrack, RenderOptions], Frames]


def reported_frames(states: Sequence[State], track: FingerTrack,
                    host_us: np.ndarray | None = None) -> Frames:
    """The targets a device reported, as frames on the track's time base (spec Q5).

    Each STATE report carries ``host_time_echo_us``, the host time of the last finger sample
    the device applied; ``host_us`` are the host times sent with the track's samples
    (:attr:`hcard.device.play.PlayResult.host_us`; by default the track's own times),
    so an echo names the sample of this session it applied, and an echo of an earlier session
    (a device that stays powered between runs) names none. Reports before the first applied
    sample of the session are left out. Report times are those of :func:`session_times`:
    exact on a protocol 1.3 device, never earlier than the truth on an older one.
    """
    keep, t = session_times(states, track, host_us, ECHO_MARGIN_PERIODS)
    uv = np.array([s.target_uv for s in states], dtype=float)
    ev = np.array([s.target_ev for s in states], dtype=float)
    contact = np.array([bool(s.contact) for s in states])
    texture = np.array([s.texture for s in states], dtype=np.int32)
    return Frames(t=t[keep], uv=uv[keep], ev=ev[keep], contact=contact[keep],
                  texture=texture[keep])


def session_times(states: Sequence[State], track: FingerTrack, host_us: np.ndarray | None = None,
                  margin_periods: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Which reports belong to the session (from the first that echoes one of its samples on)
    and every report's time on the track's time base, s.

    A protocol 1.3 device says how long before each report it placed the sample it echoes
    (``echo_age_us``, rule PI3): the report's time is that sample's track time plus the age,
    exactly, even where the device's clock offset (PO2) moved within the session. An older
    device does not, and the offset is estimated: the smallest delay between a sample's time
    and the first report echoing it, less ``margin_periods`` report periods (a sample is
    applied up to one period before the first report that echoes it), so that mapped times
    are never earlier than the truth and at most about a period plus the transport delay later
    (a lag that the lag search of metric A1 absorbs; see :data:`ECHO_MARGIN_PERIODS`).
    """
    from hcard.device.protocol.constants import ECHO_AGE_UNKNOWN, TIME_UNIT_S
    from hcard.device.recording import HOST_TIME_MODULO, echoed_samples, unwrapped_times
    from hcard.device.state_log import state_field

    if host_us is None:
        host_us = np.rint(track.t * US_PER_S).astype(np.int64) % HOST_TIME_MODULO
    device_t = unwrapped_times(states) if states else np.zeros(0)
    echo = state_field(states, "host_time_echo_us").astype(np.int64)
    sample = echoed_samples(host_us, echo)
    applied = sample >= 0
    if not np.any(applied):
        return np.zeros(len(states), dtype=bool), device_t
    keep = np.arange(len(states)) >= np.flatnonzero(applied)[0]
    echo_s = track.t[np.maximum(sample, 0)]
    ages_us = state_field(states, "echo_age_us")[applied]
    if not np.any(ages_us == ECHO_AGE_UNKNOWN):  # every applied report says its echo's age
        exact = echo_s[applied] + ages_us * TIME_UNIT_S  # State.echo_age_s, per report
        offset = float(np.median(device_t[applied] - exact))
        t = device_t - offset  # reports that echo no sample of the session: not kept
        t[applied] = exact
        return keep, t
    first = np.flatnonzero(applied & np.concatenate(([True], sample[1:] != sample[:-1])))
    period = float(np.median(np.diff(device_t))) if len(states) > 1 else 0.0
    offset = float(np.min(device_t[first] - echo_s[first])) - margin_periods * period
    return keep, device_t - offset


@dataclass
class Context:
    """The implementation under test, the vectors and run options.

    Attributes:
        driver_name: ``reference``, a device URI, or ``control:NAME``.
        open_driver: opens a fresh driver (None for ``reference``, which has no device).
        vectors_root: the vectors directory (``spec/vectors``).
        options: free-form options for checks (for example ``{"tail_s": 0.05}``).
        renderer: override of :meth:`render` (tests use it to plant a wrong renderer).
        selected_cases: the cases wanted of some checks, by check name (a run of part of a
            check, such as pytest's ``-k``); a check not named here runs all its cases
            (:meth:`wants`).
    """

    driver_name: str
    open_driver: Callable[[], Driver] | None = None
    vectors_root: Path = DEFAULT_VECTORS
    options: dict[str, Any] = field(default_factory=dict)
    renderer: Renderer | None = None
    cache: dict[Any, Any] = field(default_factory=dict, repr=False)
    selected_cases: dict[str, frozenset[str]] = field(default_factory=dict)
    _manifest: Any = field(default=None, init=False, repr=False)

    def wants(self, check: str, case: str) -> bool:
        """Whether ``check`` is to measure ``case``: yes unless :attr:`selected_cases` names
        the check without the case. A check whose cases are measured one by one skips the
        cases not wanted; one that measures them together measures them all, and whoever
        selected keeps the results it wants."""
        chosen = self.selected_cases.get(check)
        return chosen is None or case in chosen

    def device_info(self) -> DeviceInfo:
        """DEVICE_INFO of the implementation's device, read once per Context (the driver is
        opened and closed for it): what a check whose cases depend on the device declares
        them from before it runs (:func:`hcard_conformance.registry.declared_cases`).

        Raises:
            ValueError: the implementation has no device (``reference``).
            HcardError, OSError: the driver's own errors opening it.
        """
        if self.open_driver is None:
            raise ValueError(f"{self.driver_name} has no device: no DEVICE_INFO")
        if DEVICE_INFO_KEY not in self.cache:
            with self.open_driver() as driver:
                self.cache[DEVICE_INFO_KEY] = driver.info()
        info: DeviceInfo = self.cache[DEVICE_INFO_KEY]
        return info

    @property
    def frame_exact(self) -> bool:
        """True when the implementation renders frame by frame at the golden frame times (the
        reference, or a software renderer given as :attr:`renderer`), so the exact metric A0
        applies; False for a driver, whose reports are resampled."""
        return self.open_driver is None

    @property
    def manifest(self) -> Any:
        """The vectors' :class:`hcard_conformance.vectors.Manifest` (loaded once)."""
        if self._manifest is None:
            from hcard_conformance.vectors import load_manifest

            self._manifest = load_manifest(Path(self.vectors_root))
        return self._manifest

    def card(self, name: str) -> pb.Card:
        """The vectors' card ``name`` (binary form), read and validated once per Context: the
        render entries that share a card share it (do not modify it)."""
        key = ("card", name)
        if key not in self.cache:
            self.cache[key] = self.manifest.card(name).load_card()
        card: pb.Card = self.cache[key]
        return card

    def render(self, card: pb.Card, track: FingerTrack, options: RenderOptions) -> Frames:
        """Target friction of ``card`` (validated: :meth:`card`) along ``track`` as this
        implementation renders it.

        Reference: :func:`hcard.render.render` with ``options`` (frames at the golden frame
        times), the card not validated again. A driver: the targets its reports carry
        (:func:`reported_frames`); ``options`` do not apply, the device renders with its own
        settings (and checks the card it is sent).
        """
        if self.renderer is not None:
            return self.renderer(card, track, options)
        if self.open_driver is None:
            return reference_render(card, track, options, check=False)
        from hcard.device.play import play

        with self.open_driver() as driver:
            self.cache[REALTIME_KEY] = driver.realtime
            result = play(driver, card, track, **({"tail_s": self.options["tail_s"]}
                                                  if "tail_s" in self.options else {}))
        from hcard_conformance.realtime import clock_mismatch, device_lag

        self.cache[DEVICE_LAG_KEY] = device_lag(result.states)
        self.cache[CLOCK_MISMATCH_KEY] = clock_mismatch(result.states)
        return reported_frames(result.states, track, result.host_us)

    @classmethod
    def for_driver(cls, name: str, *, vectors_root: Path | None = None,
                   options: dict[str, Any] | None = None) -> Context:
        """A Context for ``reference`` or a device URI (``sim://``, ``control:NAME``, ...).

        The driver is not opened here; an unknown name fails on first use with the driver's
        own error.
        """
        root = Path(vectors_root) if vectors_root is not None else DEFAULT_VECTORS
        opts = dict(options or {})
        if name == REFERENCE:
            return cls(REFERENCE, None, root, opts)
        from hcard.device import open_device

        return cls(name, lambda: open_device(name), root, opts)
