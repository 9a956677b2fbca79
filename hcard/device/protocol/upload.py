"""The device side of the card upload (spec/device-protocol.md section 9): a staging buffer, the
CRC-32 check and the atomic swap, as a state machine independent of USB; the card check runs
between :meth:`UploadStore.stage_commit` and :meth:`UploadStore.finish_card` outside the
device's lock (:mod:`hcard_device.card_check`, rule PU12).

The previous card stays active until a COMMIT succeeds; every failure frees the staging buffer,
records why (UPLOAD_STATUS) and leaves the active card alone.
"""

from __future__ import annotations

from dataclasses import dataclass

from hcard.device.protocol.codec import crc32
from hcard.device.protocol.constants import (
    UPLOAD_DETAIL_BYTES,
    UPLOAD_TIMEOUT_S,
    UploadResult,
    UploadState,
)
from hcard.device.protocol.reports import UploadBegin, UploadData, UploadStatus
from hcard.errors import CardValidationError, HcardError
from hcard.v1 import card_pb2 as pb


@dataclass(frozen=True)
class StagedUpload:
    """The bytes of an upload handed over by a COMMIT to the checks that run outside the
    device's lock (rule PU12): the CRC-32 (:meth:`crc_matches`), then the card or profile.

    Attributes:
        serial: which upload (a BEGIN starts a new one).
        buffer: the bytes received (their length checked). The store never changes it again:
            a BEGIN or a failure gives the store a new staging buffer.
        crc32: the CRC-32 announced by UPLOAD_BEGIN.
    """

    serial: int
    buffer: bytearray
    crc32: int

    def crc_matches(self) -> bool:
        """The CRC-32 of the bytes is the one announced (PU3; 2 MiB take ~2 ms, so outside
        the lock)."""
        return crc32(self.buffer) == self.crc32


@dataclass
class ActiveCard:
    """The card in force.

    Attributes:
        card: the parsed, validated card.
        data: its bytes as uploaded.
        crc32: CRC-32 of ``data``.
        generation: successful COMMITs since power-up when it was committed (wrapping u16,
            never 0).
    """

    card: pb.Card
    data: bytes
    crc32: int
    generation: int


def detail_text(text: str) -> tuple[str, bool]:
    """``text`` as the ASCII detail field (non-ASCII and control characters as ``?``), cut to
    46 bytes; returns (detail, truncated)."""
    clean = "".join(ch if " " <= ch <= "~" else "?" for ch in text)
    return clean[:UPLOAD_DETAIL_BYTES], len(clean) > UPLOAD_DETAIL_BYTES


def failure_detail(exc: HcardError) -> str:
    """The field path of the first problem of a card error, or the start of its reason."""
    if isinstance(exc, CardValidationError) and exc.problems:
        first = exc.problems[0]
        return first.path or first.reason
    path = getattr(exc, "field_path", "")
    return path or str(getattr(exc, "reason", exc))


class UploadStore:
    """Staging buffer and active card of one device.

    Args:
        max_card_bytes: largest card accepted, bytes.
        timeout_s: an upload with no upload report for this long (device time) fails, s.

    Every method takes the current device time ``now_s`` (s) for the timeout.
    """

    def __init__(self, max_card_bytes: int, timeout_s: float = UPLOAD_TIMEOUT_S) -> None:
        if max_card_bytes < 1:
            raise ValueError(f"max_card_bytes must be >= 1, got {max_card_bytes}")
        self.max_card_bytes = max_card_bytes
        self.timeout_s = timeout_s
        self.state = UploadState.IDLE
        self.result = UploadResult.OK
        self.detail = ""
        self.detail_truncated = False
        self.total_length = 0
        self.expected_crc = 0
        self.received = 0
        self.active: ActiveCard | None = None
        self._generation = 0
        self._staging = bytearray()
        self._last_activity_s = 0.0
        self._serial = 0
        self.checking = False
        """The staged bytes of a COMMIT are being checked (:meth:`stage_commit`)."""

    # ---- requests ---------------------------------------------------------------------------

    def begin(self, report: UploadBegin, now_s: float) -> bool:
        """UPLOAD_BEGIN (rule PU1). Returns False when the upload failed at once."""
        self._reset_staging()
        self._serial += 1
        self.checking = False
        self.received = 0
        self.total_length = report.total_length
        self.expected_crc = report.crc32
        self._last_activity_s = now_s
        if report.total_length == 0:
            return self._fail(UploadResult.EMPTY)
        if report.total_length > self.max_card_bytes:
            return self._fail(UploadResult.TOO_LARGE)
        self.state = UploadState.RECEIVING
        self.result = UploadResult.OK
        self.detail, self.detail_truncated = "", False
        return True

    def data(self, report: UploadData, now_s: float) -> bool:
        """UPLOAD_DATA (rule PU2). Returns False when the chunk failed the upload."""
        if self.poll(now_s):
            return False
        if self.state != UploadState.RECEIVING:
            return self._not_started()
        self._last_activity_s = now_s
        if report.offset != self.received:
            return self._fail(UploadResult.OUT_OF_ORDER)
        if self.received + len(report.data) > self.total_length:
            return self._fail(UploadResult.TOO_LARGE)
        self._staging += report.data
        self.received += len(report.data)
        return True

    def stage_commit(self, now_s: float) -> StagedUpload | None:
        """UPLOAD_END COMMIT or COMMIT_PROFILE, first step (rules PU3, PU9): check the length,
        then hand the staged bytes over for the CRC-32 and the card or profile check, which
        run outside the device's lock (rule PU12). The upload stays RECEIVING (its timeout
        suspended) until :meth:`finish_card`, :meth:`finish_profile` or :meth:`fail_check`.
        None when the COMMIT is decided already: the upload failed (the reason in
        UPLOAD_STATUS), or the staged bytes are being checked already (nothing changes)."""
        if self.checking:
            return None
        data = self._staged(now_s)
        if data is None:
            return None
        self.checking = True
        return StagedUpload(self._serial, data, self.expected_crc)

    def is_staged(self, staged: StagedUpload) -> bool:
        """The upload ``staged`` is still the one being checked (no BEGIN discarded it and no
        request failed it meanwhile)."""
        return (self.checking and self.state == UploadState.RECEIVING
                and staged.serial == self._serial)

    def finish_card(self, staged: StagedUpload, card: pb.Card, data: bytes) -> bool:
        """The checked ``card`` (``data``, the bytes of ``staged``) is in force: it becomes the
        active card (PU3). True."""
        self._generation = self._generation % 0xFFFF + 1
        self.active = ActiveCard(card, data, staged.crc32, self._generation)
        return self._committed()

    def finish_profile(self) -> bool:
        """The checked profile is in force (PU9); the active card stays. True."""
        return self._committed()

    def fail_check(self, result: UploadResult, detail: str) -> bool:
        """The check refused the staged bytes (INVALID_CARD, INVALID_PROFILE, or BUSY when a
        session began meanwhile): the upload fails, the active card stays. False."""
        return self._fail(result, detail)

    def _staged(self, now_s: float) -> bytearray | None:
        """The staging buffer when a COMMIT may go ahead (receiving, complete; its CRC-32 is
        checked next, :meth:`StagedUpload.crc_matches`); None after failing the upload with
        the reason otherwise. O(1): the buffer is handed over, not copied."""
        if self.poll(now_s):
            return None
        if self.state != UploadState.RECEIVING:
            self._not_started()
            return None
        if self.received != self.total_length:
            self._fail(UploadResult.SHORT)
            return None
        return self._staging

    def _committed(self) -> bool:
        self._reset_staging()
        self.checking = False
        self.state = UploadState.COMMITTED
        self.result = UploadResult.OK
        self.detail, self.detail_truncated = "", False
        return True

    def abort(self, now_s: float) -> bool:
        """UPLOAD_END ABORT (rule PU4): fails a receiving upload; ignored otherwise.
        Returns True (ABORT is never refused)."""
        self.poll(now_s)
        if self.state == UploadState.RECEIVING:
            self._fail(UploadResult.ABORTED)
        return True

    def poll(self, now_s: float) -> bool:
        """Fail a receiving upload that has been silent for ``timeout_s`` (rule PU4); True
        when this call failed it."""
        if (
            self.state == UploadState.RECEIVING
            and not self.checking  # the host waits for its COMMIT's status stage (PU12)
            and now_s - self._last_activity_s >= self.timeout_s
        ):
            self._fail(UploadResult.TIMEOUT)
            return True
        return False

    # ---- read back --------------------------------------------------------------------------

    @property
    def generation(self) -> int:
        """Generation of the active card, 0 without one."""
        return self.active.generation if self.active else 0

    def status(self) -> UploadStatus:
        """The UPLOAD_STATUS report."""
        return UploadStatus(
            state=int(self.state),
            result=int(self.result),
            detail_flags=UploadStatus.DETAIL_TRUNCATED if self.detail_truncated else 0,
            received=self.received,
            total_length=self.total_length,
            active_crc32=self.active.crc32 if self.active else 0,
            card_generation=self.generation,
            detail=self.detail,
        )

    def begin_readback(self) -> UploadBegin:
        """UPLOAD_BEGIN as read back: the upload in progress, zeros when none."""
        if self.state != UploadState.RECEIVING:
            return UploadBegin(0, 0)
        return UploadBegin(self.total_length, self.expected_crc)

    def data_readback(self) -> UploadData:
        """UPLOAD_DATA as read back: the next offset expected, no data."""
        return UploadData(self.received if self.state == UploadState.RECEIVING else 0, b"")

    # ---- internals --------------------------------------------------------------------------

    def busy(self, detail: str) -> bool:
        """COMMIT or COMMIT_PROFILE refused because a host's session is live (rule PN5): the
        upload fails with BUSY and ``detail``; the active card and profile stay. False."""
        return self._fail(UploadResult.BUSY, detail)

    def _not_started(self) -> bool:
        # A failed upload keeps its first reason until the next BEGIN; otherwise NOT_STARTED.
        if self.state == UploadState.FAILED:
            return False
        return self._fail(UploadResult.NOT_STARTED)

    def _fail(self, result: UploadResult, detail: str = "") -> bool:
        self._reset_staging()
        self.checking = False
        self.state = UploadState.FAILED
        self.result = result
        self.detail, self.detail_truncated = detail_text(detail)
        return False

    def _reset_staging(self) -> None:
        self._staging = bytearray()
