"""Error types of the hcard core.

Every failure caused by user input (a file, a card, a track, an image) raises a subclass of
:class:`HcardError`. The command line turns these into a one-line message and a non-zero exit;
anything else escaping is a bug.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


class HcardError(Exception):
    """Base class of all user-facing hcard errors."""


@dataclass(frozen=True)
class Problem:
    """One validation finding.

    Attributes:
        path: field path in the card, for example ``textures[2].components[0].frequency``.
        reason: what is wrong, in words.
        severity: ``"error"`` (the card must be rejected) or ``"warning"`` (it renders, but not
            as written, for example a UV texture whose swing is clipped at 1).
        rule: the rule of spec/README.md broken (``"T4"``), empty when none applies.
    """

    path: str
    reason: str
    severity: str = "error"
    rule: str = ""

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}" if self.path else self.reason


class CardError(HcardError):
    """A card could not be read or written.

    The documented error type of the card reader: corrupt or truncated bytes, bad JSON, an
    unsupported major version and failed validation all raise this (or a subclass).
    """

    def __init__(self, reason: str, *, source: str | Path | None = None, path: str = "") -> None:
        self.reason = reason
        self.source = str(source) if source is not None else None
        self.field_path = path
        where = ": ".join(part for part in (self.source, path) if part)
        super().__init__(f"{where}: {reason}" if where else reason)


class CardValidationError(CardError):
    """A card parsed but breaks the rules of spec/README.md; ``problems`` lists every error."""

    def __init__(self, problems: list[Problem], *, source: str | Path | None = None) -> None:
        self.problems = [p for p in problems if p.severity == "error"]
        first = self.problems[0] if self.problems else Problem("", "invalid card")
        more = len(self.problems) - 1
        reason = first.reason + (f" (and {more} more problem{'s' * (more > 1)})" if more else "")
        super().__init__(reason, source=source, path=first.path)


class TrackError(HcardError):
    """A finger track file or array is malformed."""


class ImageError(HcardError):
    """An image cannot be encoded (not an image, empty, too large)."""


class PluginError(HcardError):
    """A requested plugin is missing or unusable."""
