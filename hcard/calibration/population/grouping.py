"""Recordings sorted into the groups of a population fit by a sidecar label
(spec/measurement-format.md MF14, spec/calibration.md K19).

``participant`` is the sidecar key ``participant``; ``session`` the key ``label`` of the
sidecar object ``session``; ``device`` the required key ``device``.
"""

from __future__ import annotations

from collections.abc import Sequence

from hcard.calibration.measurement import Measurement
from hcard.errors import InputError

GROUPINGS = ("participant", "session", "device")
"""What a population fit groups recordings by."""


class PopulationError(InputError):
    """Recordings or fits that cannot make a population (the message names what and where)."""


def without_samples(m: Measurement) -> Measurement:
    """``m``'s conditions, source and first sample only: what grouping and the choice of the
    base model read, kept for every recording while the samples of each are dropped as soon
    as it is read (a study's recordings are never all in memory at once; the tasks read their
    own again where they run)."""
    return Measurement(t=m.t[:1].copy(), normal_force=m.normal_force[:1].copy(),
                       lateral_force=m.lateral_force[:1].copy(), conditions=m.conditions,
                       source=m.source)


def label_of(m: Measurement, by: str) -> str | None:
    """The label of recording ``m`` under the grouping ``by`` (:data:`GROUPINGS`), or None when
    its sidecar has none (an empty or blank string counts as none).

    Raises:
        PopulationError: the label is not a string, or ``by`` is not a grouping.
    """
    if by not in GROUPINGS:
        raise PopulationError(f"cannot group by {by!r}; groupings: {', '.join(GROUPINGS)}")
    if by == "session":
        session = m.conditions.get("session")
        value = session.get("label") if isinstance(session, dict) else None
        key = "session.label"
    else:
        value, key = m.conditions.get(by), by
    if value is None:
        return None
    if not isinstance(value, str):
        raise PopulationError(f"{m.source or 'recording'}.json: sidecar key {key!r} must be a "
                              f"string, got {type(value).__name__} (rule MF14)")
    return value.strip() or None


def group_recordings(measurements: Sequence[Measurement], by: str = "participant"
                     ) -> dict[str, list[Measurement]]:
    """The recordings by label (:func:`label_of`), labels in order of first appearance, each
    group's recordings in the order given.

    Raises:
        PopulationError: a recording without the label (all of them named, up to 5), or fewer
            than 2 groups (a population needs two members to have a spread).
    """
    groups: dict[str, list[Measurement]] = {}
    missing: list[str] = []
    for index, m in enumerate(measurements):
        label = label_of(m, by)
        if label is None:
            missing.append(m.source or f"recording {index + 1}")
        else:
            groups.setdefault(label, []).append(m)
    key = "session.label" if by == "session" else by
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5
                                          else "")
        raise PopulationError(
            f"{len(missing)} recording(s) have no {by} label (sidecar key {key!r}, rule MF14): "
            f"{shown}; label every recording or group by another key (--by)")
    if len(groups) < 2:
        found = next(iter(groups), None)
        raise PopulationError(
            f"a population needs at least 2 {by}s; the recordings name "
            + (f"only {found!r}" if found else "none")
            + " (use hcard calibrate run for one)")
    return groups
