"""Devices simulated in this process: what the host library asks of whoever provides them.

The host library simulates no device. ``sim://`` URIs and the ``loopback`` host of
``usbip://`` and ``pyusb://`` name a device simulated in this process; the driver plugin of the
scheme ``sim`` provides it (the hcard reference device, package ``hcard_device``, does), found
through the plugin registry like every driver. The provider has, beside a driver's ``open``
and ``enumerate``:

* ``resolve_model(uri, variant, options) -> DeviceUri``: the URI with its model options
  (``device``, ``seed``, ``effect``, ``EFFECT.PARAM``) checked and filled in, raising
  :class:`~hcard.device.errors.UriError` naming the URI and the option;
* ``serve_in_process(uri)``: the device of a ``loopback`` URI, started in this process: an
  object with ``transport`` (whose ``connect()`` returns a connected socket of a socket pair)
  and ``stop()``.

A device served in this process says so (:func:`note_serving`), so that a driver that must not
share the process with it (hidapi: closing a hidraw node whose USB/IP server runs in the same
process can deadlock in the kernel) can refuse clearly.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

from hcard.device.errors import UriError

if TYPE_CHECKING:
    from hcard.device.uri import DeviceUri

PROVIDER_SCHEME = "sim"
"""The scheme whose driver plugin provides the devices simulated in this process."""

_serving: set[int] = set()
_serving_lock = threading.Lock()


def provider(uri_text: str) -> Any:
    """The driver of :data:`PROVIDER_SCHEME`, loaded.

    Raises:
        UriError: no installed driver plugin provides in-process devices (naming ``uri_text``).
    """
    from hcard.device.open import driver_classes

    plugin = driver_classes().get(PROVIDER_SCHEME)
    if plugin is None:
        raise UriError(f"bad device URI {uri_text!r}: it names a device simulated in this "
                       "process, and no installed driver provides one (the reference device, "
                       "package hcard_device, does)")
    return plugin.load() if hasattr(plugin, "load") else plugin


def resolve_model(uri: DeviceUri, variant: str, options: dict[str, str]) -> DeviceUri:
    """``uri`` with its model options checked by the provider (see the module docstring)."""
    return provider(uri.text).resolve_model(uri, variant, options)


def serve_in_process(uri: DeviceUri) -> Any:
    """The device of the ``loopback`` URI ``uri``, started in this process by the provider."""
    return provider(uri.text).serve_in_process(uri)


def note_serving(server: object, serving: bool) -> None:
    """A device server in this process started (``serving``) or stopped."""
    with _serving_lock:
        if serving:
            _serving.add(id(server))
        else:
            _serving.discard(id(server))


def serving_in_process() -> bool:
    """True while a device server runs in this process."""
    with _serving_lock:
        return bool(_serving)
