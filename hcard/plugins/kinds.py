"""Base classes of the plugin kinds. Plugins may subclass them or just match their shape."""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hcard.v1 import card_pb2 as pb

KINDS = ("encoder", "predictor", "driver", "calibration-effect", "conformance-check")
"""Plugin kinds, in the order ``hcard plugins`` lists them."""


@dataclass
class EncodeResult:
    """What an encoder produced: the card and figures for the summary.

    ``stats`` holds named figures (for example ``rms_error``), ``log`` lines of notes, ``maps``
    per-taxtel arrays of shape (rows, cols) (for example ``error_rms``, relative friction).
    """

    card: pb.Card
    stats: dict[str, Any] = field(default_factory=dict)
    log: list[str] = field(default_factory=list)
    maps: dict[str, Any] = field(default_factory=dict)


class Encoder(abc.ABC):
    """Turns a source file into a card."""

    kind = "encoder"
    name: str = ""
    description: str = ""

    @abc.abstractmethod
    def encode(self, source: Path, **options: Any) -> EncodeResult:
        """Encode ``source``; options are encoder specific. Raise an HcardError on bad input."""
