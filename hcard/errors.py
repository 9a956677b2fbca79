"""Error types of the hcard core.

Every failure caused by user input (a file, a card, a track, an image), a device or a model
raises a subclass of :class:`HcardError`. The command line turns these into a one-line message
and a non-zero exit; anything else escaping is a bug. The one hierarchy, by kind:

- :class:`InputError`: a file or value given is malformed: :class:`CardError` (and
  :class:`CardValidationError`), :class:`TrackError`, :class:`ImageError`,
  ``json_text.JsonInputError``, ``bounded_read.InputTooLarge``,
  ``calibration.measurement.MeasurementError``, ``quantities.UnitError``,
  ``physics.sweep.SweepError`` and the device's ``HiddenEffectError``. Those that were
  ``ValueError`` before still are.
- :class:`UsageError`: a request that cannot be carried out as asked: the commands'
  ``*UsageError``, ``calibration.plan.PlanError``, ``render.renderer.RenderTooLong`` and the
  device's ``PlayTooLong`` and ``UriError``.
- :class:`PluginError`: a plugin is missing or unusable.
- ``physics.predictor.PredictorError``: a model's parameters or inputs (``ProfileError``,
  ``EffectError``).
- ``hcard.device.errors.DeviceError``: the device failed (``DeviceTimeout``, also a
  :class:`TimeoutError`; ``DeviceStall``, ``SessionBusy``, ``SessionLost``), and
  ``hcard.device.protocol.base.ProtocolError`` for malformed reports.
- The conformance suite's ``CannotAssess``, and its pytest plugin's ``ConformanceFailure`` and
  ``CaseNotFound`` (a node ID naming no declared case).
"""

from __future__ import annotations

import os
from dataclasses import dataclass


class HcardError(Exception):
    """Base class of all user-facing hcard errors."""


class InputError(HcardError):
    """A file or value given to hcard is malformed (the message names where and why)."""


class UsageError(HcardError):
    """A request that cannot be carried out as asked (options that do not fit together, a
    rendering or play that would last too long)."""


@dataclass(frozen=True)
class Problem:
    """One validation finding.

    Attributes:
        path: field path in the card, for example ``textures[2].components[0].frequency``.
        reason: what is wrong, in words.
        severity: ``"error"`` (the card must be rejected) or ``"warning"`` (it renders, but not
            as written, for example a UV texture whose swing is clipped at 1).
        rule: the rule of spec/README.md broken (``"T4"``), empty when none applies.
        count: how many problems this one stands for: 1, or for the summary of the problems
            of one rule that a bounded report does not list, their number
            (:class:`hcard.validate.Findings`).
    """

    path: str
    reason: str
    severity: str = "error"
    rule: str = ""
    count: int = 1

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}" if self.path else self.reason


def problem_count(problems: list[Problem]) -> int:
    """How many problems ``problems`` stands for: the listed ones and those the summaries
    count (:attr:`Problem.count`)."""
    return sum(problem.count for problem in problems)


class CardError(InputError):
    """A card could not be read or written.

    The documented error type of the card reader: corrupt or truncated bytes, bad JSON, an
    unsupported major version and failed validation all raise this (or a subclass).
    """

    def __init__(self, reason: str, *, source: str | os.PathLike[str] | None = None,
                 path: str = "") -> None:
        self.reason = reason
        self.source = str(source) if source is not None else None
        self.field_path = path
        where = ": ".join(part for part in (self.source, path) if part)
        super().__init__(f"{where}: {reason}" if where else reason)


class CardValidationError(CardError):
    """A card parsed but breaks the rules of spec/README.md; ``problems`` lists every error."""

    def __init__(self, problems: list[Problem], *,
                 source: str | os.PathLike[str] | None = None) -> None:
        self.problems = [p for p in problems if p.severity == "error"]
        first = self.problems[0] if self.problems else Problem("", "invalid card")
        more = problem_count(self.problems) - 1
        reason = first.reason + (f" (and {more} more problem{'s' * (more > 1)})" if more else "")
        super().__init__(reason, source=source, path=first.path)


class TrackError(InputError):
    """A finger track file or array is malformed."""


class ImageError(InputError):
    """An image cannot be encoded (not an image, empty, too large)."""


class AssetError(InputError):
    """Another tool's asset (a Tanvas or TPad bitmap, an Interhaptics .haps, an MPEG .hjif)
    cannot be imported: the message names the file, the field (a JSON path such as
    ``perceptions[0].channels[1].bands[0]``) and why."""

    def __init__(self, reason: str, *, source: str | os.PathLike[str] | None = None,
                 field: str = "") -> None:
        self.reason = reason
        self.source = str(source) if source is not None else None
        self.field = field
        where = ": ".join(part for part in (self.source, field) if part)
        super().__init__(f"{where}: {reason}" if where else reason)


class PluginError(HcardError):
    """A requested plugin is missing or unusable."""
