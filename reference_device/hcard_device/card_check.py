"""The checks of a COMMIT (is it a valid card? a device profile?), off the device's real-time
path (spec/device-protocol.md rule PU12).

Parsing and validating a card of up to ``max_card_bytes`` (2 MiB) costs from milliseconds (a
1.3 MB binary card: 30 ms) to much longer for hostile input, and much of it runs in C
(``json.loads``, the protobuf parser) holding Python's global interpreter lock: a parse on
another thread of the device's process still stops its firmware thread. So the served device
checks in a **worker process** (:class:`ProcessChecker`, ``python -m hcard_device.card_check``):
the firmware sends it the staged bytes without holding its lock, waits at most
:data:`CHECK_TIMEOUT_S` (the bound of spec/README.md section 4 for any card command on any card
under 16 MiB), and gets back everything the device needs to render the card: the card compiled
for the renderer (0.06 s of Python for the largest valid card), its textures' extremes for the
clip report (0.15 s), and the card itself as :func:`pieces <card_pieces>`, its header and one
piece per texture, each a binary card that parses in well under a millisecond, merged in order
into the card the device keeps (protobuf merges repeated fields by appending), so that no
single step of the device's process holds the interpreter lock for long. A worker that does
not answer in time is killed (and replaced): the upload fails with INVALID_CARD
(INVALID_PROFILE) and a detail naming the bound, and the device never stalls.

:class:`InlineChecker` checks in the calling thread (still outside the firmware's lock): the
in-process ``sim://`` device, whose time only moves when its host advances it, and tests.
"""

from __future__ import annotations

import contextlib
import io
import os
import pickle
import select
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import IO, Protocol

from hcard.card_io import parse_card
from hcard.device.protocol.upload import failure_detail
from hcard.errors import HcardError
from hcard.physics.card_clipping import TextureExtremes, card_extremes
from hcard.physics.profile import DeviceProfile
from hcard.render.compiled import CompiledCard, compile_card
from hcard.render.options import RenderOptions
from hcard.v1 import card_pb2 as pb

CHECK_TIMEOUT_S = 20.0
"""Longest wait for the check of one COMMIT or COMMIT_PROFILE, waiting for an earlier check
included, s (spec/README.md section 4: every card command on any card under 16 MiB finishes
within 20 s)."""
WORKER_NICENESS = 10
"""CPU niceness of the worker process (the device's real-time process keeps its own)."""
WORKER_START_TIMEOUT_S = 30.0
"""Longest wait for a new worker process to say it is ready, s (it imports the card reader)."""
_FRAME = struct.Struct(">I")
_CARD, _PROFILE = b"C", b"P"
_READY = b"ready"


@dataclass(frozen=True)
class CheckedCard:
    """A valid card, compiled.

    Attributes:
        pieces: the card, as pieces to merge (:func:`assemble_card`).
        compiled: its compiled form for the renderer (:func:`hcard.render.compiled.compile_card`
            with the options of the check).
        extremes: what each texture the grid uses asks at its extremes (the clip report's card
            part, :func:`~hcard.physics.card_clipping.card_extremes`).
    """

    pieces: tuple[bytes, ...]
    compiled: CompiledCard
    extremes: tuple[TextureExtremes, ...]


@dataclass(frozen=True)
class CheckedProfile:
    """A device profile that parsed (its channels are checked against the device later)."""

    profile: DeviceProfile


@dataclass(frozen=True)
class CheckFailed:
    """Why the bytes are not a valid card or profile: the field path of the first problem or
    the start of the reason (UPLOAD_STATUS ``detail``, rule PU8)."""

    detail: str


CardOutcome = CheckedCard | CheckFailed
ProfileOutcome = CheckedProfile | CheckFailed


class Checker(Protocol):
    """What the firmware needs to check a COMMIT (:class:`InlineChecker`,
    :class:`ProcessChecker`)."""

    def check_card(self, data: bytes, options: RenderOptions) -> CardOutcome: ...

    def check_profile(self, data: bytes) -> ProfileOutcome: ...

    def close(self) -> None: ...


INDEX_PIECE = 8192
"""Taxtel indices per piece of :func:`card_pieces` (the largest grid has 65 536)."""


def card_pieces(card: pb.Card) -> tuple[bytes, ...]:
    """``card`` as binary pieces whose merge in order is ``card``: everything but the textures
    and the taxtel indices, the indices :data:`INDEX_PIECE` at a time, then one piece per
    texture (proto3 leaves default scalars out of a piece, and a merge appends repeated
    fields, so each piece adds only what it holds)."""
    head = pb.Card()
    head.CopyFrom(card)
    del head.textures[:]
    del head.grid.texture_index[:]
    indices = card.grid.texture_index
    return (head.SerializeToString(),
            *(pb.Card(grid=pb.TaxtelGrid(texture_index=indices[i:i + INDEX_PIECE]))
              .SerializeToString() for i in range(0, len(indices), INDEX_PIECE)),
            *(pb.Card(textures=[texture]).SerializeToString() for texture in card.textures))


def assemble_card(pieces: tuple[bytes, ...]) -> pb.Card:
    """The card of :func:`card_pieces`: each piece merged in order (each parse holds the
    interpreter lock for well under a millisecond, even for the largest valid card)."""
    card = pb.Card()
    for piece in pieces:
        card.MergeFromString(piece)
    return card


def check_card_bytes(data: bytes, options: RenderOptions) -> CardOutcome:
    """Parse and validate a card (binary or JSON form, README.md F5), then compile it for a
    renderer with ``options`` and find its textures' extremes."""
    try:
        card = parse_card(data, source="upload")
        compiled = compile_card(card, options)
    except HcardError as exc:
        return CheckFailed(failure_detail(exc))
    return CheckedCard(card_pieces(card), compiled, card_extremes(card))


def check_profile_bytes(data: bytes) -> ProfileOutcome:
    """Parse a device profile (spec/device-profile.md)."""
    try:
        return CheckedProfile(DeviceProfile.from_json(data, source="profile"))
    except HcardError as exc:
        return CheckFailed(str(exc))


class InlineChecker:
    """Checks in the calling thread (see the module docstring)."""

    def check_card(self, data: bytes, options: RenderOptions) -> CardOutcome:
        """:func:`check_card_bytes`."""
        return check_card_bytes(data, options)

    def check_profile(self, data: bytes) -> ProfileOutcome:
        """:func:`check_profile_bytes`."""
        return check_profile_bytes(data)

    def close(self) -> None:
        """Nothing to release."""


class ProcessChecker:
    """Checks in a worker process, one check at a time, each bounded by ``timeout_s``
    (waiting for an earlier check included; see the module docstring).

    Args:
        timeout_s: longest wait for one check, s.
        log: writes one line to the device's log (a worker killed or lost).

    :meth:`start` starts the worker; one killed is replaced in the background; :meth:`close`
    ends it.
    """

    def __init__(self, timeout_s: float = CHECK_TIMEOUT_S,
                 log: Callable[[str], None] | None = None) -> None:
        self.timeout_s = float(timeout_s)
        self._log = log
        self._lock = threading.Lock()
        self._process: subprocess.Popen[bytes] | None = None
        self._closed = False
        self.killed = 0
        """Workers killed because a check took longer than ``timeout_s``."""

    def start(self) -> ProcessChecker:
        """Start the worker and wait until it is ready (at most
        :data:`WORKER_START_TIMEOUT_S`; a worker that is not ready then is started again by
        the first check)."""
        self._start_in_background()
        return self

    def _start_in_background(self) -> None:
        if not self._lock.acquire(timeout=self.timeout_s):
            return
        try:
            if not self._closed:
                self._ensure_worker(time.monotonic() + WORKER_START_TIMEOUT_S)
        except OSError:
            pass  # the next check starts it again and reports why
        finally:
            self._lock.release()

    def check_card(self, data: bytes, options: RenderOptions) -> CardOutcome:
        """Check a card in the worker; CheckFailed when it is invalid or not checked in time."""
        outcome = self._check(_CARD, data, "card", options)
        if isinstance(outcome, CheckedCard | CheckFailed):
            return outcome
        return CheckFailed("card check: the worker answered nonsense")

    def check_profile(self, data: bytes) -> ProfileOutcome:
        """Check a device profile in the worker, like :meth:`check_card`."""
        outcome = self._check(_PROFILE, data, "profile", None)
        if isinstance(outcome, CheckedProfile | CheckFailed):
            return outcome
        return CheckFailed("profile check: the worker answered nonsense")

    def _check(self, kind: bytes, data: bytes, what: str,
               options: RenderOptions | None) -> object:
        deadline = time.monotonic() + self.timeout_s
        late = CheckFailed(f"{what} not checked within {self.timeout_s:g} s")
        if not self._lock.acquire(timeout=self.timeout_s):
            return late
        try:
            if self._closed:
                return CheckFailed(f"{what} check: the device is stopping")
            try:
                process = self._ensure_worker(deadline)
                assert process.stdin is not None and process.stdout is not None
                _write_frame(process.stdin, kind + pickle.dumps(options) + data)
                return _read_outcome(process.stdout, deadline)
            except TimeoutError:
                self._kill(f"a {what} check took longer than {self.timeout_s:g} s")
                return late
            except (OSError, EOFError, ValueError) as exc:
                self._kill(f"the {what} check worker failed ({exc})")
                return CheckFailed(f"{what} check failed: the checker stopped")
        finally:
            self._lock.release()

    def _ensure_worker(self, deadline: float) -> subprocess.Popen[bytes]:
        """The live worker, started (and waited for) when there is none."""
        process = self._process
        if process is not None and process.poll() is None:
            return process
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(path for path in sys.path if path)
        process = subprocess.Popen(
            [sys.executable, "-m", "hcard_device.card_check"], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, env=env)
        self._process = process
        assert process.stdout is not None
        try:
            ready = _read_frame(process.stdout, min(deadline, time.monotonic()
                                                    + WORKER_START_TIMEOUT_S))
        except (TimeoutError, EOFError, ValueError) as exc:
            self._kill("")
            raise OSError(f"the check worker did not start ({exc})") from None
        if ready != _READY:
            self._kill("")
            raise OSError("the check worker did not start")
        return process

    def _kill(self, reason: str) -> None:
        process, self._process = self._process, None
        if process is None:
            return
        report = bool(reason) and not self._closed
        if report:
            self.killed += 1
            if self._log is not None:
                self._log(f"killed the card check worker: {reason}")
        with contextlib.suppress(OSError):
            process.kill()
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(5.0)
        for stream in (process.stdin, process.stdout):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()
        if report:
            self.start_later()

    def start_later(self) -> None:
        """Start a replacement worker in the background once the lock is free."""
        threading.Thread(target=self._start_in_background, daemon=True,
                         name="hcard-card-check-restart").start()

    @property
    def worker_pid(self) -> int | None:
        """The worker's process ID (None when there is none)."""
        process = self._process
        return process.pid if process is not None and process.poll() is None else None

    def close(self) -> None:
        """End the worker (a check in progress fails)."""
        self._closed = True
        process = self._process
        if process is not None:
            with contextlib.suppress(OSError):
                process.kill()
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(5.0)
        with self._lock:
            self._kill("")


def _write_frame(stream: IO[bytes], payload: bytes) -> None:
    stream.write(_FRAME.pack(len(payload)))
    stream.write(payload)
    stream.flush()


def _read_frame(stream: IO[bytes], deadline: float) -> bytes:
    """One length-prefixed frame from a pipe, waiting until ``deadline`` at most.

    Raises:
        TimeoutError: the deadline passed first.
        EOFError: the other end closed.
    """
    fd = stream.fileno()
    head = _read_exactly(fd, _FRAME.size, deadline)
    (size,) = _FRAME.unpack(head)
    return _read_exactly(fd, size, deadline)


def _read_exactly(fd: int, size: int, deadline: float) -> bytes:
    chunks = bytearray()
    while len(chunks) < size:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError("no answer in time")
        ready, _, _ = select.select([fd], [], [], remaining)
        if not ready:
            continue
        chunk = os.read(fd, min(size - len(chunks), 1 << 20))
        if not chunk:
            raise EOFError("the worker closed its pipe")
        chunks += chunk
    return bytes(chunks)


def _blobs(outcome: object) -> tuple[tuple[object, ...], list[bytes]]:
    """An outcome as a small header and blobs, each unpickled on its own by the device
    (:func:`_read_outcome`): the card's pieces, each field of its compiled form (each texture
    apart) and each texture's extremes; none takes long to load."""
    if isinstance(outcome, CheckedCard):
        compiled = outcome.compiled
        fields = [name for name in vars(compiled) if name != "textures"]
        blobs = [*outcome.pieces,
                 *(pickle.dumps(getattr(compiled, name)) for name in fields),
                 *(pickle.dumps(texture) for texture in compiled.textures),
                 *(pickle.dumps(entry) for entry in outcome.extremes)]
        return ("card", len(outcome.pieces), tuple(fields), len(compiled.textures),
                len(outcome.extremes)), blobs
    return ("object",), [pickle.dumps(outcome)]


def _write_outcome(stream: IO[bytes], outcome: tuple[tuple[object, ...], list[bytes]]) -> None:
    """Write an outcome made into a header and blobs by :func:`_blobs`."""
    header, blobs = outcome
    _write_frame(stream, pickle.dumps((header, len(blobs))))
    for blob in blobs:
        _write_frame(stream, blob)


def _read_outcome(stream: IO[bytes], deadline: float) -> object:
    """An outcome written by :func:`_write_outcome` (the worker is trusted: it is the
    device's own process)."""
    header, count = pickle.loads(_read_frame(stream, deadline))
    blobs = [_read_frame(stream, deadline) for _ in range(count)]
    if header[0] != "card":
        return pickle.loads(blobs[0])
    _, pieces, fields, textures, extremes = header
    compiled = CompiledCard.__new__(CompiledCard)  # fields as they were, none recomputed
    at = pieces
    for name in fields:
        object.__setattr__(compiled, name, pickle.loads(blobs[at]))
        at += 1
    object.__setattr__(compiled, "textures",
                       tuple(pickle.loads(blob) for blob in blobs[at:at + textures]))
    at += textures
    return CheckedCard(tuple(blobs[:pieces]), compiled,
                       tuple(pickle.loads(blob) for blob in blobs[at:at + extremes]))


def _serve(stdin: IO[bytes], stdout: IO[bytes]) -> None:
    """The worker's loop: one check per frame, one answer per check, until stdin closes. It
    runs at a lower CPU priority (:data:`WORKER_NICENESS`): on a machine with few cores, a
    20 s check of hostile input must not take the CPU from the device's real-time process.
    A process inherits its parent's scheduling: started by a device server running at
    ``SCHED_RR``, the worker first goes back to ordinary scheduling (else the nice value means
    nothing, and a check ran ahead of every ordinary process and beside the device's threads
    at their priority)."""
    with contextlib.suppress(OSError, AttributeError):
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    with contextlib.suppress(OSError):
        os.nice(WORKER_NICENESS)
    _write_frame(stdout, _READY)
    while True:
        head = stdin.read(_FRAME.size)
        if len(head) < _FRAME.size:
            return
        (size,) = _FRAME.unpack(head)
        payload = stdin.read(size)
        if len(payload) < size:
            return
        kind, rest = payload[:1], io.BytesIO(payload[1:])
        options = pickle.load(rest)  # the request comes from the device: trusted
        data = rest.read()
        outcome: object
        try:
            outcome = (check_card_bytes(data, options) if kind == _CARD
                       else check_profile_bytes(data))
            blobs = _blobs(outcome)
        except MemoryError:
            blobs = _blobs(CheckFailed("the card needs more memory than the checker has"))
        except Exception as exc:  # a defect of the checker: said in the upload's detail
            blobs = _blobs(CheckFailed(f"the checker failed ({type(exc).__name__}: {exc})"))
        _write_outcome(stdout, blobs)


if __name__ == "__main__":
    # the answers' classes must be pickled under this module's name, not __main__'s
    from hcard_device.card_check import _serve as serve

    serve(sys.stdin.buffer, sys.stdout.buffer)
