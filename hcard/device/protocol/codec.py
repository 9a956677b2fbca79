"""Dispatch by report kind and ID, plus the host-side helpers every driver shares: the report
sequence of a card upload and the STREAM reports of a block of frames."""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from typing import TYPE_CHECKING

from hcard.device.protocol.base import ProtocolError, Report
from hcard.device.protocol.constants import (
    MAX_REPORT_BYTES,
    STREAM_FRAMES_PER_REPORT,
    UPLOAD_CHUNK_BYTES,
    ReportKind,
    UploadAction,
)
from hcard.device.protocol.reports import (
    REPORT_CLASSES,
    State,
    Stream,
    UploadBegin,
    UploadData,
    UploadEnd,
)

if TYPE_CHECKING:
    import numpy as np

_BY_KEY: dict[tuple[ReportKind, int], type[Report]] = {
    (cls.KIND, cls.REPORT_ID): cls for cls in REPORT_CLASSES
}


def report_class(kind: ReportKind | int, report_id: int) -> type[Report]:
    """The report class of a kind and ID.

    Raises:
        ProtocolError: no report of that kind has that ID (a device answers with STALL).
    """
    try:
        kind = ReportKind(kind)
    except ValueError:
        raise ProtocolError(f"unknown report kind {kind}") from None
    cls = _BY_KEY.get((kind, report_id))
    if cls is None:
        raise ProtocolError(f"no {kind.name.lower()} report with ID 0x{report_id & 0xFF:02X}")
    return cls


def report_ids(kind: ReportKind | int) -> tuple[int, ...]:
    """IDs of every report of a kind, ascending."""
    return tuple(sorted(rid for k, rid in _BY_KEY if k == kind))


def decode(kind: ReportKind | int, data: bytes | bytearray | memoryview) -> Report:
    """Decode a report of the given kind (report ID byte first).

    Raises:
        ProtocolError: empty, longer than 64 bytes, unknown ID for the kind, or malformed.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise ProtocolError(f"expected bytes, got {type(data).__name__}")
    if len(data) == 0:
        raise ProtocolError("empty report: no report ID byte")
    if len(data) > MAX_REPORT_BYTES:
        raise ProtocolError(f"{len(data)} bytes exceed the {MAX_REPORT_BYTES}-byte report limit")
    return report_class(kind, data[0]).decode(data)


def decode_input(data: bytes | bytearray | memoryview) -> State:
    """Decode an input report (the host side of the interrupt IN endpoint)."""
    report = decode(ReportKind.INPUT, data)
    assert isinstance(report, State)
    return report


def decode_output(data: bytes | bytearray | memoryview) -> Report:
    """Decode an output report (the device side of interrupt OUT / SET_REPORT(Output))."""
    return decode(ReportKind.OUTPUT, data)


def decode_feature(data: bytes | bytearray | memoryview) -> Report:
    """Decode a feature report (either direction of GET/SET_REPORT(Feature))."""
    return decode(ReportKind.FEATURE, data)


def encode(report: Report) -> bytes:
    """The wire bytes of a report (report ID first)."""
    return report.encode()


def crc32(data: bytes | bytearray) -> int:
    """CRC-32 of the upload integrity check: ISO-HDLC (zlib, Ethernet), u32."""
    return zlib.crc32(data) & 0xFFFF_FFFF


def upload_reports(data: bytes, action: UploadAction = UploadAction.COMMIT) -> list[bytes]:
    """The feature reports (SET_REPORT, in order) that upload and commit ``data``:
    UPLOAD_BEGIN, UPLOAD_DATA chunks of 58 bytes, UPLOAD_END(``action``: COMMIT for a card,
    COMMIT_PROFILE for a device profile)."""
    if not data:
        raise ProtocolError("cannot upload an empty file")
    out = [UploadBegin(len(data), crc32(data)).encode()]
    for offset in range(0, len(data), UPLOAD_CHUNK_BYTES):
        chunk = bytes(data[offset : offset + UPLOAD_CHUNK_BYTES])
        out.append(UploadData(offset, chunk).encode())
    out.append(UploadEnd(action).encode())
    return out


def stream_reports(uv: Sequence[float] | np.ndarray, ev: Sequence[float] | np.ndarray,
                   first_seq: int = 0) -> list[bytes]:
    """STREAM output reports carrying the frames (relative friction: UV in [0, 1], EV in [1, 4]),
    15 frames each, sequence numbers from ``first_seq`` (wrapping u16)."""
    if len(uv) != len(ev):
        raise ProtocolError(f"uv has {len(uv)} frames but ev has {len(ev)}")
    out = []
    for n, start in enumerate(range(0, len(uv), STREAM_FRAMES_PER_REPORT)):
        stop = start + STREAM_FRAMES_PER_REPORT
        out.append(Stream.from_friction(first_seq + n, uv[start:stop], ev[start:stop]).encode())
    return out
