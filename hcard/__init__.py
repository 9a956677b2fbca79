"""hcard: the haptic-card standard and toolkit for friction-modulation touchscreens.

Cards are ``hcard.v1.card_pb2.Card`` protobuf messages (re-exported as :data:`Card`).

>>> import hcard
>>> card = hcard.load("surface.hcard")          # doctest: +SKIP
>>> problems = hcard.validate(card)              # doctest: +SKIP
>>> from hcard.render import render
>>> frames = render(card, track)                 # doctest: +SKIP
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from hcard.validate import validate  # eager: the submodule of that name would shadow it
from hcard.version import __version__

if TYPE_CHECKING:
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

_LAZY = {
    **dict.fromkeys(("dumps", "load", "parse_card", "save", "to_json"), "hcard.card_io"),
    **dict.fromkeys(("CardError", "CardValidationError", "HcardError", "ImageError",
                     "PluginError", "Problem", "TrackError"), "hcard.errors"),
    **dict.fromkeys(("Card", "Component", "Texture"), "hcard.v1.card_pb2"),
}
"""The module of each name, imported on first use: a command that reads no card (``hcard
plugins``, ``hcard --help``) does not load the card reader and its JSON form (30 ms)."""


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hcard' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


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
