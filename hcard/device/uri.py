"""Device URIs: which driver talks to which device, parsed with clear errors.

=====================================  ===========================================================
``sim://`` ``sim://coupled?seed=3``    in-process firmware and simulation, advanced by the driver
``usbip://HOST:PORT/BUSID``            USB/IP client (default ``usbip://127.0.0.1:3240/1-1``)
``usbip://loopback?device=coupled``    USB/IP to a device served in this process (socket pair)
``pyusb://HOST:PORT/BUSID``            pyusb through the in-process USB/IP backend
``pyusb://loopback?device=evita``      pyusb to a device served in this process
``hid://1209:0001`` ``hid://``         hidapi: first device with this VID:PID (hex; default ours)
``hid:///dev/hidraw0``                 hidapi: the device at this path
=====================================  ===========================================================

``device`` (``evita`` or ``coupled``), ``seed`` (integer) and hidden physical effects apply to
``sim://`` and ``loopback``: ``effect=NAME[,NAME]`` switches effects on and ``NAME.PARAM=VALUE``
sets a parameter (units accepted; it switches its effect on too), as ``hcard device serve
--effect`` does: ``sim://coupled?effect=air-layer&air-layer.air_gap=8um``
(the reference device's hidden effects, ``hcard device serve --list-effects``), and
``ambient_pressure`` (units accepted, ``ambient_pressure=50kPa``) the air around its plate (one
atmosphere by default; a play records it in the sidecar as ``ambient_pressure_pa``). The model
options are checked by the provider of
in-process devices (:mod:`hcard.device.in_process`). Parsing never touches a device.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from urllib.parse import parse_qsl, urlsplit

from hcard.device.errors import UriError
from hcard.device.protocol.usb_ids import PID, VID
from hcard.device.transports.usbip_connect import DEFAULT_BUSID, DEFAULT_HOST, DEFAULT_PORT

SCHEMES = ("sim", "usbip", "pyusb", "hid")
"""URI schemes of the built-in drivers."""
LOOPBACK_HOST = "loopback"
"""Host name meaning: serve the device in this process and connect through a socket pair."""
DEFAULT_VARIANT = "evita"

_EXAMPLES = {
    "sim": "sim:// or sim://coupled?seed=1",
    "usbip": "usbip://127.0.0.1:3240/1-1 or usbip://loopback?device=evita",
    "pyusb": "pyusb://127.0.0.1:3240/1-1 or pyusb://loopback?device=evita",
    "hid": "hid://1209:0001 or hid:///dev/hidraw0",
}
_BUSID = re.compile(r"^[0-9]+-[0-9]+(\.[0-9]+)*$")
_VIDPID = re.compile(r"^([0-9A-Fa-f]{1,4}):([0-9A-Fa-f]{1,4})$")


@dataclass(frozen=True)
class DeviceUri:
    """A parsed device URI.

    Attributes:
        text: the URI as given.
        scheme: ``sim``, ``usbip``, ``pyusb`` or ``hid`` (or a plugin's scheme).
        host, port, busid: USB/IP server and bus ID (``usbip``/``pyusb``).
        path: device node (``hid:///dev/hidrawN``), "" otherwise.
        vid, pid: USB IDs to look for (``hid://VID:PID``).
        variant: device model served in-process (``sim``, ``loopback``): evita or coupled.
        seed: random seed of the in-process simulation.
        effects: physical effects hidden in the in-process device: name -> parameter values.
        ambient_pressure_pa: air pressure around the in-process device's plate, Pa (None: one
            atmosphere, not stated).
        options: every query option, as given.
    """

    text: str
    scheme: str
    host: str = ""
    port: int = 0
    busid: str = ""
    path: str = ""
    vid: int = VID
    pid: int = PID
    variant: str = DEFAULT_VARIANT
    seed: int = 0
    effects: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    ambient_pressure_pa: float | None = None
    options: Mapping[str, str] = field(default_factory=dict)

    @property
    def loopback(self) -> bool:
        """The device is served in this process (``usbip``/``pyusb`` with host ``loopback``)."""
        return self.host == LOOPBACK_HOST

    def __str__(self) -> str:
        return self.text


def ambient_pressure(text: str) -> float:
    """The ``ambient_pressure`` option's value in Pa (units accepted: ``50kPa``, ``0.5atm``).

    Raises:
        ValueError: not a pressure, or not finite and > 0.
    """
    import math

    from hcard.quantities import parse_quantity

    value = parse_quantity(text.strip(), "Pa")
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"ambient_pressure {text!r} must be a pressure > 0")
    return value


def stated_ambient_pressure(text: str) -> float | None:
    """The ambient pressure (Pa) the query of the device URI ``text`` states, None when it
    states none or a malformed one (an in-process device's option, which a recording keeps as
    its condition ``ambient_pressure_pa``)."""
    value = dict(parse_qsl(urlsplit(str(text)).query)).get("ambient_pressure")
    if value is None:
        return None
    try:
        return ambient_pressure(value)
    except ValueError:
        return None


def uri_error(text: str, scheme: str, reason: str) -> UriError:
    """The error of a bad URI ``text`` of ``scheme``: the URI, the ``reason`` and an example."""
    example = _EXAMPLES.get(scheme, " or ".join(_EXAMPLES.values()))
    return UriError(f"bad device URI {text!r}: {reason} (expected e.g. {example})")


def parse_uri(text: str, *, schemes: tuple[str, ...] = SCHEMES) -> DeviceUri:
    """Parse a device URI; ``schemes`` lists the schemes accepted (plugins add theirs, in the
    form ``SCHEME://...`` or ``SCHEME:NAME``, e.g. the negative controls' ``control:lossy``).

    Raises:
        UriError: malformed, unknown scheme, bad port, bus ID, VID:PID, option or variant.
    """
    if not isinstance(text, str) or ":" not in text:
        raise uri_error(str(text), "", "a device URI has the form SCHEME://...")
    scheme = text.split(":", 1)[0].lower()
    if scheme in SCHEMES and not text[len(scheme):].startswith("://"):
        raise uri_error(text, scheme, "a device URI has the form SCHEME://...")
    if scheme not in schemes:
        if "://" not in text:  # neither a known scheme nor a URI
            raise uri_error(text, "", "a device URI has the form SCHEME://...")
        raise UriError(
            f"bad device URI {text!r}: unknown scheme {scheme!r} (known: {', '.join(schemes)})"
        )
    parts = urlsplit(text)
    if parts.fragment:
        raise uri_error(text, scheme, "a device URI has no #fragment")
    options = dict(parse_qsl(parts.query, keep_blank_values=True))
    if scheme not in SCHEMES:
        return DeviceUri(text, scheme, host=parts.netloc, path=parts.path, options=options)
    if scheme == "hid":
        return _parse_hid(text, parts.netloc, parts.path, options)
    if scheme == "sim":
        if parts.path not in ("", "/"):
            raise uri_error(text, scheme, f"sim:// takes no path (got {parts.path!r})")
        variant = parts.netloc or options.get("device", DEFAULT_VARIANT)
        return _with_model(DeviceUri(text, scheme, options=options), text, variant, options)
    return _parse_usbip(text, scheme, parts.netloc, parts.path, options)


def _with_model(uri: DeviceUri, text: str, variant: str, options: dict[str, str]) -> DeviceUri:
    """``uri`` with its model options checked by the provider of in-process devices
    (:func:`hcard.device.in_process.resolve_model`)."""
    from hcard.device import in_process

    return in_process.resolve_model(uri, variant, options)


def _parse_usbip(text: str, scheme: str, netloc: str, path: str,
                 options: dict[str, str]) -> DeviceUri:
    host, port = DEFAULT_HOST, DEFAULT_PORT
    if netloc:
        host_part, port_part = netloc, ""
        if netloc.startswith("["):  # [IPv6]:port
            close = netloc.find("]")
            if close < 0:
                raise uri_error(text, scheme, "unclosed '[' in the host")
            host_part, port_part = netloc[1:close], netloc[close + 1:].removeprefix(":")
        elif ":" in netloc:
            host_part, port_part = netloc.rsplit(":", 1)
        if "@" in host_part:
            raise uri_error(text, scheme, "a device URI has no user name")
        host = host_part or DEFAULT_HOST
        if port_part:
            if not port_part.isdigit() or not 0 < int(port_part) < 65536:
                raise uri_error(text, scheme, f"port {port_part!r} is not a number in 1..65535")
            port = int(port_part)
    busid = path.strip("/") or DEFAULT_BUSID
    if not _BUSID.match(busid):
        raise uri_error(text, scheme, f"bus ID {busid!r} is not of the form 1-1 or 1-1.2")
    uri = DeviceUri(text, scheme, host=host, port=port, busid=busid, options=options)
    if host == LOOPBACK_HOST:
        return _with_model(uri, text, options.get("device", DEFAULT_VARIANT), options)
    if options:
        raise uri_error(text, scheme, f"unknown option(s) {', '.join(sorted(options))} "
                     "(options apply to loopback only)")
    return uri


def _parse_hid(text: str, netloc: str, path: str, options: dict[str, str]) -> DeviceUri:
    if options:
        raise uri_error(text, "hid", f"unknown option(s) {', '.join(sorted(options))}")
    if netloc and path not in ("", "/"):
        raise uri_error(text, "hid", "give either VID:PID or a device path, not both")
    if netloc:
        match = _VIDPID.match(netloc)
        if not match:
            raise uri_error(text, "hid", f"{netloc!r} is not VID:PID in hexadecimal")
        return DeviceUri(text, "hid", vid=int(match[1], 16), pid=int(match[2], 16))
    if path not in ("", "/"):
        return DeviceUri(text, "hid", path=path)
    return DeviceUri(text, "hid")
