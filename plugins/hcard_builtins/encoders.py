"""Built-in encoder plugins: the ``image`` encoder (:mod:`hcard_builtins.image`)."""

from __future__ import annotations

from hcard.plugins.hookspecs import hookimpl
from hcard_builtins.image import ImageEncoder


@hookimpl
def hcard_encoders() -> list[ImageEncoder]:
    """The built-in encoders."""
    return [ImageEncoder()]
