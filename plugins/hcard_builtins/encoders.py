"""Built-in encoder plugins: the ``image`` encoder (:mod:`hcard_builtins.image`, imported when
the hook is called, so that discovering the plugins does not load NumPy and Pillow)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from hcard.plugins.hookspecs import hookimpl

if TYPE_CHECKING:
    from hcard_builtins.image import ImageEncoder


@hookimpl
def hcard_encoders() -> list[ImageEncoder]:
    """The built-in encoders."""
    from hcard_builtins.image import ImageEncoder

    return [ImageEncoder()]
