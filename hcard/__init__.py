"""hcard: the haptic-card standard and toolkit for friction-modulation touchscreens.

Cards are ``hcard.v1.card_pb2.Card`` protobuf messages (re-exported as :data:`Card`).

>>> import hcard
>>> card = hcard.load("surface.hcard")          # doctest: +SKIP
>>> problems = hcard.validate(card)              # doctest: +SKIP
>>> from hcard.render import render
>>> frames = render(card, track)                 # doctest: +SKIP
"""

from __future__ import annotations

from hcard.card_io import dumps, load, parse_card, save, to_json
from hcard.errors import (
    CardError,
    CardValidationError,
    HcardError,
    ImageError,
    PluginError,
    Problem,
    TrackError,
)
from hcard.v1.card_pb2 import Card, Component, Texture
from hcard.validate import validate
from hcard.version import __version__

__all__ = [
    "Card",
    "CardError",
    "CardValidationError",
    "Component",
    "HcardError",
    "ImageError",
    "PluginError",
    "Problem",
    "Texture",
    "TrackError",
    "__version__",
    "dumps",
    "load",
    "parse_card",
    "save",
    "to_json",
    "validate",
]
