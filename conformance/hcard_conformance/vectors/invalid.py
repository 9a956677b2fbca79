"""Invalid vector cards: each must be rejected with its documented error fragment and field.

Every vector starts from one small valid card and breaks exactly one rule. ``error`` is a text
fragment of the reference reader's message (``CardError.reason``), ``field`` the field path it
reports (``CardError.field_path``; empty when the bytes cannot be parsed at all).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass

from hcard import build, card_io
from hcard.v1 import card_pb2 as pb


@dataclass(frozen=True)
class InvalidVector:
    """One invalid card file.

    Attributes:
        name: vector name.
        extension: ``.hcard`` (binary) or ``.json``.
        data: the file bytes.
        error: fragment of the reference error text.
        field: field path of the error, ``""`` when none.
        rule: the spec rule it breaks (README section 5 or 8).
    """

    name: str
    extension: str
    data: bytes
    error: str
    field: str
    rule: str


def base_card() -> pb.Card:
    """The valid card every invalid vector is derived from (20 x 10 mm, one UV grating)."""
    tex = build.texture(0.7, [build.spatial(1.0, 0.2)], channel="uv", locking="velocity",
                        name="grating")
    card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[tex], title="invalid vector base")
    card.metadata.generator = "hcard_conformance.vectors"
    return card


def _binary(mutate: Callable[[pb.Card], None]) -> bytes:
    card = base_card()
    mutate(card)
    return card.SerializeToString(deterministic=True)


def _json(mutate: Callable[[dict], None]) -> bytes:
    obj = json.loads(card_io.to_json(base_card()))
    mutate(obj)
    return (json.dumps(obj, indent=2) + "\n").encode("utf-8")


def _set(path: tuple[str | int, ...], value: object) -> Callable[[dict], None]:
    def mutate(obj: dict) -> None:
        target = obj
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value

    return mutate


def _delete(path: tuple[str | int, ...]) -> Callable[[dict], None]:
    def mutate(obj: dict) -> None:
        target = obj
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]

    return mutate


def _extra_components(card: pb.Card) -> None:
    card.textures[0].components.extend(build.spatial(1.0 + i, 0.01) for i in range(16))


def _no_columns(card: pb.Card) -> None:
    card.grid.cols = 0
    del card.grid.texture_index[:]


def _one_column(card: pb.Card) -> None:
    """One 10 mm column on the 20 mm surface, with its one index: only G4 is broken."""
    card.grid.cols = 1
    del card.grid.texture_index[1:]


def _extra_textures(card: pb.Card) -> None:
    card.textures.extend(build.texture(0.5, [], channel="uv", locking="velocity", name=f"t{i}")
                         for i in range(256))


def _set_attr(getter: Callable[[pb.Card], object], name: str, value: object
              ) -> Callable[[pb.Card], None]:
    def mutate(card: pb.Card) -> None:
        setattr(getter(card), name, value)

    return mutate


def _truncated(good: bytes) -> bytes:
    """The longest prefix of at most half of ``good`` that protobuf refuses to parse (the cut
    falls inside a field, not between two fields)."""
    for size in range(len(good) // 2, 0, -1):
        try:
            pb.Card().ParseFromString(good[:size])
        except Exception:
            return good[:size]
    raise AssertionError("no truncation of the base card fails to parse")


def invalid_vectors() -> list[InvalidVector]:
    """Every invalid vector, in manifest order."""
    good = base_card().SerializeToString(deterministic=True)
    comp = "textures[0].components[0]"
    return [
        InvalidVector("empty", ".hcard", b"", "empty input", "", "F6"),
        InvalidVector("truncated", ".hcard", _truncated(good),
                      "corrupt or truncated card bytes", "", "F7"),
        InvalidVector("corrupt", ".hcard", b"\x08\x01\x12\xff\xff\xff\xff\x0f",
                      "corrupt or truncated card bytes", "", "F7"),
        InvalidVector("bad-json", ".json", b'{"version": \n', "not valid JSON", "", "F7"),
        InvalidVector("wrong-major", ".hcard",
                      _binary(_set_attr(lambda c: c.version, "major", 2)),
                      "unsupported major version 2.0", "version.major", "V1"),
        InvalidVector("missing-version", ".json", _json(_delete(("version",))),
                      "missing format version", "version", "V1"),
        InvalidVector("nan-amplitude", ".json",
                      _json(_set(("textures", 0, "components", 0, "amplitude"), "NaN")),
                      "must be finite", f"{comp}.amplitude", "C3"),
        InvalidVector("infinite-baseline", ".hcard",
                      _binary(_set_attr(lambda c: c.textures[0], "baseline", math.inf)),
                      "must be finite", "textures[0].baseline", "T3"),
        InvalidVector("infinite-phase", ".json",
                      _json(_set(("textures", 0, "components", 0, "phase"), "-Infinity")),
                      "finite", f"{comp}.phase", "C4"),
        InvalidVector("zero-frequency", ".hcard",
                      _binary(_set_attr(lambda c: c.textures[0].components[0], "frequency",
                                        0.0)),
                      "must be > 0", f"{comp}.frequency", "C2"),
        InvalidVector("negative-frequency", ".json",
                      _json(_set(("textures", 0, "components", 0, "frequency"), -1.0)),
                      "must be > 0", f"{comp}.frequency", "C2"),
        InvalidVector("too-many-components", ".hcard", _binary(_extra_components),
                      "17 components exceed the limit of 16", "textures[0].components", "T7"),
        InvalidVector("grid-size-mismatch", ".hcard",
                      _binary(lambda c: c.grid.texture_index.append(0)),
                      "has 3 entries but the grid is 2 x 1 = 2 taxtels", "grid.texture_index",
                      "G5"),
        InvalidVector("index-outside-palette", ".json",
                      _json(_set(("grid", "texture_index", 1), 3)),
                      "outside the palette", "grid.texture_index[1]", "G6"),
        InvalidVector("missing-channel", ".json", _json(_delete(("textures", 0, "channel"))),
                      "must be CHANNEL_UV, CHANNEL_EV or CHANNEL_BIPOLAR",
                      "textures[0].channel", "T4"),
        InvalidVector("uv-baseline-above-1", ".hcard",
                      _binary(_set_attr(lambda c: c.textures[0], "baseline", 1.2)),
                      "UV can only lower friction", "textures[0].baseline", "T6"),
        InvalidVector("long-title", ".json", _json(_set(("metadata", "title"), "x" * 1025)),
                      "1025 characters, over the limit of 1024", "metadata.title", "M1"),
        InvalidVector("zero-width", ".hcard",
                      _binary(_set_attr(lambda c: c.surface, "width_mm", 0.0)),
                      "must be > 0 mm", "surface.width_mm", "G1"),
        InvalidVector("tiny-taxtel", ".json", _json(_set(("grid", "taxtel_width_mm"), 0.01)),
                      "must be at least 0.05 mm", "grid.taxtel_width_mm", "G2"),
        InvalidVector("no-columns", ".hcard", _binary(_no_columns), "must be at least 1",
                      "grid.cols", "G3"),
        InvalidVector("grid-short-of-surface", ".hcard", _binary(_one_column),
                      "cover 10 mm, less than the surface (20 mm)", "grid.cols", "G4"),
        InvalidVector("too-many-textures", ".hcard", _binary(_extra_textures),
                      "257 textures exceed the limit of 256", "textures", "T1"),
        InvalidVector("duplicate-texture-name", ".hcard",
                      _binary(lambda c: c.textures.append(c.textures[0])),
                      "duplicate name 'grating'", "textures[1].name", "T2"),
        InvalidVector("missing-locking", ".json", _json(_delete(("textures", 0, "locking"))),
                      "must be LOCKING_POSITION, LOCKING_VELOCITY or LOCKING_AUTO",
                      "textures[0].locking", "T5"),
        InvalidVector("missing-domain", ".json",
                      _json(_delete(("textures", 0, "components", 0, "domain"))),
                      "must be DOMAIN_SPATIAL or DOMAIN_TEMPORAL", f"{comp}.domain", "C1"),
        InvalidVector("unknown-channel", ".hcard",
                      _binary(_set_attr(lambda c: c.textures[0].components[0], "channel", 9)),
                      "unknown channel 9", f"{comp}.channel", "C5"),
    ]
