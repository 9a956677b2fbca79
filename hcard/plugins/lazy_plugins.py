"""Plugins named by import path: a driver (:class:`LazyDriver`, a
:class:`~hcard.plugins.kinds.DriverPlugin`) and an encoder (:class:`LazyEncoder`, an
:class:`~hcard.plugins.kinds.EncoderPlugin`).

Listing the plugins (``hcard plugins``, :func:`~hcard.plugins.registry.get_registry`) needs a
plugin's name and description only (and a driver's URI schemes); the plugin itself (a driver's
transport library and protocol codec, an encoder's image library and renderer) is imported when
it is first used. The built-in drivers and encoders are registered this way, and a vendor's may
be::

    from hcard.plugins import LazyDriver, hookimpl

    @hookimpl
    def hcard_drivers():
        return [LazyDriver("acme", "ACME plate over its serial link: acme://PORT", ("acme",),
                           "acme_hcard.driver:AcmeDriver")]
"""

from __future__ import annotations

import functools
import pkgutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NamedTuple


class LazyDriver(NamedTuple):
    """A driver known by name, description and schemes until it is used.

    Attributes:
        name: the driver's name (``"hid"``).
        description: one line: what it reaches, with the URI form.
        schemes: URI schemes it opens (``("hid",)``).
        target: ``"package.module:attribute"`` of the driver (an object with ``open`` and
            ``enumerate``, usually a ``Driver`` class), imported on first use.
    """

    name: str
    description: str
    schemes: tuple[str, ...]
    target: str

    @property
    def kind(self) -> str:
        """``"driver"``."""
        return "driver"

    def load(self) -> Any:
        """Import :attr:`target` and return the driver it names."""
        return pkgutil.resolve_name(self.target)

    def open(self, uri: Any, **options: Any) -> Any:
        """The loaded driver's ``open(uri, **options)``: a connected driver."""
        return self.load().open(uri, **options)

    def enumerate(self, hosts: Sequence[tuple[str, int]] = (), **options: Any) -> list[Any]:
        """The loaded driver's ``enumerate(hosts, **options)``: the devices it reaches now."""
        return list(self.load().enumerate(hosts, **options))


class LazyEncoder(NamedTuple):
    """An encoder known by name and description until it is used.

    Attributes:
        name: the encoder's name (``"image"``).
        description: one line: what it turns into a card.
        target: ``"package.module:attribute"`` of a callable taking no arguments that returns
            the encoder (usually its class), imported and called once, on first use.
    """

    name: str
    description: str
    target: str

    @property
    def kind(self) -> str:
        """``"encoder"``."""
        return "encoder"

    def load(self) -> Any:
        """The encoder :attr:`target` makes (one per target and process)."""
        return _made(self.target)

    def options(self, **values: Any) -> dict[str, Any]:
        """The loaded encoder's ``options(**values)``."""
        options: dict[str, Any] = self.load().options(**values)
        return options

    def encode(self, source: Path, *, progress: Callable[[str], None] | None = None,
               **options: Any) -> Any:
        """The loaded encoder's ``encode(source, progress=progress, **options)``."""
        return self.load().encode(source, progress=progress, **options)


@functools.cache
def _made(target: str) -> Any:
    return pkgutil.resolve_name(target)()
