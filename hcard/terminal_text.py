"""Text from a card (metadata, texture names) made safe to print on a terminal.

A card is written by a stranger: an ESC sequence in its title would reach the terminal as a
command (move the cursor, rewrite the screen, set the window title, or with some terminals
write files), and a right-to-left override would make a problem line read as something else.
:func:`printable` shows each such character as an escape a reader can see instead.
"""

from __future__ import annotations

import re

UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069]")
"""Characters a terminal acts on rather than shows: the C0 and C1 control characters (ESC,
CSI, OSC, BEL, CR, LF, ...), DEL, and the Unicode bidirectional marks, embeddings, overrides
and isolates."""


def _escape(match: re.Match[str]) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code <= 0xFF else f"\\u{code:04x}"


def printable(text: str) -> str:
    """``text`` with every :data:`UNSAFE` character replaced by its escape (``\\x1b``,
    ``\\u202e``): one line, shown as written, never acted on."""
    return UNSAFE.sub(_escape, text)
