"""Built-in encoder plugins: the ``image`` encoder (:class:`hcard_builtins.image.ImageEncoder`),
as a :class:`~hcard.plugins.lazy_plugins.LazyEncoder`, so that listing the plugins imports
neither Pillow nor the renderer; the encoder is made when it is first used. The name and
description below are the class's own (a test compares them)."""

from __future__ import annotations

from hcard.plugins.hookspecs import hookimpl
from hcard.plugins.lazy_plugins import LazyEncoder

BUILTIN_ENCODERS: tuple[LazyEncoder, ...] = (
    LazyEncoder("image", "Grayscale image to card (black = high friction): per-taxtel spectral "
                "analysis into a palette of grating textures",
                "hcard_builtins.image.encoder:ImageEncoder"),
)
"""The built-in encoders."""


@hookimpl
def hcard_encoders() -> list[LazyEncoder]:
    """The built-in encoders (:data:`BUILTIN_ENCODERS`)."""
    return list(BUILTIN_ENCODERS)
