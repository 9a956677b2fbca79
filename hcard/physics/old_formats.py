"""Device-profile files of earlier formats: refused, each with what to do instead.

A file whose ``format`` names one of :data:`OLD_FORMATS` is not read as a profile of today's
format (spec/device-profile.md): the error says what it is and how to get a profile of today's
format from it.
"""

from __future__ import annotations

from typing import Any

from hcard.physics.profile_error import ProfileError

OLD_FORMATS = {
    "hcard-device-profile/1": (
        "a version-1 device profile; version 2 adds the effects and the calibration: move its "
        "fields into a version-2 file (spec/device-profile.md) or write it again with hcard"
    ),
    "hcard-calibrated-profile/1": (
        "the fitted model of an earlier 'hcard calibrate', which now writes device profiles: "
        "run 'hcard calibrate' on the recordings again"
    ),
    "hcard-predictor-profile/1": (
        "a bare predictor's parameters, which a device profile (hcard-device-profile/2) now "
        "holds under 'predictor'"
    ),
}
"""Formats of earlier versions, each with what to do instead."""


def refuse_old_format(form: Any, source: str) -> None:
    """:class:`ProfileError` naming ``source`` and saying what to do, when ``form`` (a file's
    ``format`` field) is one of :data:`OLD_FORMATS`; nothing otherwise."""
    why = OLD_FORMATS.get(form) if isinstance(form, str) else None
    if why:
        raise ProfileError(f"{source}: format: {form!r} is {why}")
