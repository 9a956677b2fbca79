"""The ``hcard`` text chunk of a bitmap export: the JSON that carries the card and how its
pixels were drawn (spec/interchange/bitmaps.md IB11-IB14).

    {"format": "tanvas", "channel": "ev", "friction_range": [1.0, 1.6], "px_per_mm": 10.0,
     "pixels_sha256": "<64 hex digits>", "card": "<base64 of the binary card>"}

``format`` comes first so that a reader can tell the format from a file's first bytes
(:func:`.png_chunks.sniff_hcard_format`). ``pixels_sha256`` is the SHA-256 of the 8-bit gray
pixels as written (row-major, one byte a pixel): a bitmap edited after the export no longer
matches it, and its card is then encoded from the pixels instead (IB13).
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hcard import limits
from hcard.card_io import card_from_bytes, check_version, to_bytes
from hcard.channels import NAMES
from hcard.errors import AssetError, CardError
from hcard.json_text import JsonInputError, parse_json
from hcard.v1 import card_pb2 as pb
from hcard.validate import require_valid

KEYS = ("format", "channel", "friction_range", "px_per_mm", "pixels_sha256", "card")
"""The members of the chunk's JSON object, in the order they are written (IB12)."""
_HEX64 = re.compile(r"[0-9a-f]{64}")


@dataclass(frozen=True)
class Extension:
    """The content of an ``hcard`` chunk.

    Attributes:
        format: the bitmap format the pixels are in (``"tanvas"``, ``"tpad"``).
        channel: the channel of the pixels' friction.
        friction_range: relative friction of the range's low and high ends the pixels were
            drawn with.
        px_per_mm: the resolution asked of the export, pixels per millimetre.
        pixels_sha256: SHA-256 of the written 8-bit gray pixels, hex.
        card: the card, valid.
    """

    format: str
    channel: str
    friction_range: tuple[float, float]
    px_per_mm: float
    pixels_sha256: str
    card: pb.Card


def pixels_digest(pixels: Any) -> str:
    """SHA-256 (hex) of 8-bit gray pixels, row-major (a ``(height, width)`` uint8 array)."""
    return hashlib.sha256(memoryview(pixels).tobytes()).hexdigest()


def extension_text(extension: Extension) -> str:
    """The chunk's JSON text, ``format`` first, no spaces."""
    value = {
        "format": extension.format,
        "channel": extension.channel,
        "friction_range": list(extension.friction_range),
        "px_per_mm": extension.px_per_mm,
        "pixels_sha256": extension.pixels_sha256,
        "card": base64.b64encode(to_bytes(extension.card)).decode("ascii"),
    }
    return json.dumps(value, separators=(",", ":"))


def parse_extension(text: str, source: Path, field: str) -> Extension:
    """The :class:`Extension` of a chunk's ``text``.

    Raises:
        AssetError: naming ``field`` (the chunk) and the member: not a JSON object, a member
            missing or of the wrong type, a range or resolution out of bounds, ``card`` not
            base64, or not a valid card.
    """
    def fail(reason: str, member: str = "") -> AssetError:
        return AssetError(reason, source=source, field=f"{field} {member}".strip())

    try:
        value = parse_json(text)
    except JsonInputError as exc:
        raise fail(f"not valid JSON ({exc})") from None
    if not isinstance(value, dict):
        raise fail("not a JSON object")
    missing = [key for key in KEYS if key not in value]
    if missing:
        raise fail(f"missing member(s) {', '.join(missing)} (IB12)")
    kind = value["format"]
    if not isinstance(kind, str):
        raise fail("must be a string", "format")
    channel = value["channel"]
    if channel not in NAMES:
        raise fail(f"must be one of {', '.join(NAMES)}, got {channel!r}", "channel")
    friction_range = _range(value["friction_range"], fail)
    px_per_mm = value["px_per_mm"]
    if isinstance(px_per_mm, bool) or not isinstance(px_per_mm, int | float) or not (
            math.isfinite(px_per_mm) and px_per_mm > 0):
        raise fail(f"must be a number above 0, got {px_per_mm!r}", "px_per_mm")
    digest = value["pixels_sha256"]
    if not (isinstance(digest, str) and _HEX64.fullmatch(digest)):
        raise fail("must be 64 lower-case hex digits (SHA-256)", "pixels_sha256")
    card = _card(value["card"], source, fail)
    return Extension(kind, channel, friction_range, float(px_per_mm), digest, card)


def _range(value: Any, fail: Any) -> tuple[float, float]:
    ok = (isinstance(value, list) and len(value) == 2
          and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                  for v in value))
    if not ok or not 0 <= value[0] < value[1] <= limits.MAX_RELATIVE_FRICTION:
        raise fail(f"must be two numbers 0 <= LO < HI <= {limits.MAX_RELATIVE_FRICTION:g}, "
                   f"got {value!r}", "friction_range")
    return float(value[0]), float(value[1])


def _card(value: Any, source: Path, fail: Any) -> pb.Card:
    if not isinstance(value, str):
        raise fail("must be a base64 string", "card")
    if len(value) > 4 * math.ceil(limits.MAX_CARD_BYTES / 3):
        raise fail(f"{len(value)} base64 characters: more than a card of the limit of "
                   f"{limits.MAX_CARD_BYTES} bytes (rule F6)", "card")
    try:
        data = base64.b64decode(value, validate=True)
    except (binascii.Error, ValueError) as exc:
        raise fail(f"not base64 ({exc})", "card") from None
    try:
        card = card_from_bytes(data, source=None)
        check_version(card)
        require_valid(card)
    except CardError as exc:
        raise fail(f"not a valid card: {exc}", "card") from None
    return card
