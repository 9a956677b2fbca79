"""The actuator channels of a card: the one table every reader, writer, renderer and report
derives its channel names, enum values, groups and labels from.

A texture's channel is UV (ultrasonic friction reduction, relative friction in [0, 1]), EV
(electrovibration, friction increase, [1, 4]) or BIPOLAR (either, by the device's choice); a
component of channel ``CHANNEL_UNSPECIFIED`` takes its texture's (spec/README.md, rules T4, C5).
The renderer sums the components of each channel in its own group (rule R11).
"""

from __future__ import annotations

from typing import NamedTuple

from hcard.v1 import card_pb2 as pb


class Channel(NamedTuple):  # not a dataclass: 0.06 ms to define instead of 0.4 ms
    """One actuator channel.

    Attributes:
        name: lower-case name in user text and on the command line (``"uv"``).
        value: the card's ``Channel`` enum value (``pb.CHANNEL_UV``).
        group: column of the channel's group in the renderer's per-frame deviation array (R11).
        label: name for people, the enum name without its prefix (``"UV"``).
    """

    name: str
    value: int
    group: int
    label: str


CHANNELS: tuple[Channel, ...] = (
    Channel("uv", pb.CHANNEL_UV, 0, "UV"),
    Channel("ev", pb.CHANNEL_EV, 1, "EV"),
    Channel("bipolar", pb.CHANNEL_BIPOLAR, 2, "BIPOLAR"),
)
"""Every channel a texture may have (rule T4), in group order."""

NAMES: tuple[str, ...] = tuple(c.name for c in CHANNELS)
"""``("uv", "ev", "bipolar")``: the choices of ``--channel`` options."""
VALUE_OF_NAME: dict[str, int] = {c.name: c.value for c in CHANNELS}
"""Enum value of each channel name."""
VALUES: frozenset[int] = frozenset(c.value for c in CHANNELS)
"""The enum values a texture's channel may take (rule T4)."""
GROUP_OF_VALUE: dict[int, int] = {c.value: c.group for c in CHANNELS}
"""Deviation-array column of each channel enum value (rule R11)."""
LABEL_OF_VALUE: dict[int, str] = {c.value: c.label for c in CHANNELS}
"""``"UV"``, ``"EV"``, ``"BIPOLAR"`` by enum value."""

GROUP_UV = GROUP_OF_VALUE[pb.CHANNEL_UV]
GROUP_EV = GROUP_OF_VALUE[pb.CHANNEL_EV]
GROUP_BIPOLAR = GROUP_OF_VALUE[pb.CHANNEL_BIPOLAR]
