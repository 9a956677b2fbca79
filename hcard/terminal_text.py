"""Text from a card (metadata, texture names) made safe to print on a terminal.

A card is written by a stranger: an ESC sequence in its title would reach the terminal as a
command (move the cursor, rewrite the screen, set the window title, or with some terminals
write files), and a right-to-left override would make a problem line read as something else.
:func:`printable` shows each such character as an escape a reader can see instead. An invalid
card's text may be 16 MiB long (16.7 million control characters, printed as 67 MB of escapes
through 843 MB of memory): :func:`clipped` shows at most :data:`MAX_SHOWN_CHARS` of it.
"""

from __future__ import annotations

import re

from hcard.limits import MAX_TEXT_LENGTH

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


MAX_SHOWN_CHARS = MAX_TEXT_LENGTH
"""Most characters of one text from a card that a tool shows: all of a valid card's text
(rules M1, T2)."""


def clipped(text: str, limit: int = MAX_SHOWN_CHARS) -> str:
    """``text`` when it holds at most ``limit`` characters, else its first ``limit`` and a note
    of how many more there are (``... (16776192 more characters)``)."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text) - limit} more characters)"
