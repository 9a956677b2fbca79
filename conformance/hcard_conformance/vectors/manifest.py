"""Reading ``spec/vectors/manifest.json`` into typed entries.

Every path in the manifest is relative to the vectors directory and uses ``/``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hcard.card_io import load, parse_card, read_card_file
from hcard.render import RenderOptions
from hcard.render.options import RenderMode
from hcard.track import FingerTrack, read_track_csv
from hcard.v1 import card_pb2 as pb

MANIFEST_FORMAT = "hcard-vectors/1"
MANIFEST_NAME = "manifest.json"
RENDER_ARRAYS = ("t_s", "uv", "ev", "friction", "contact", "texture")
"""Arrays of a golden render NPZ (spec/track-format.md TO2)."""


def default_root() -> Path:
    """``spec/vectors`` of the repository this package lives in (else of the working dir)."""
    here = Path(__file__).resolve().parents[3] / "spec" / "vectors"
    return here if here.is_dir() else Path("spec") / "vectors"


@dataclass(frozen=True)
class CardEntry:
    """A valid card, in binary and JSON form."""

    name: str
    binary: Path
    json: Path
    tags: tuple[str, ...]
    description: str = ""

    def load_card(self, form: str = "binary") -> pb.Card:
        """The card parsed and validated from its ``binary`` or ``json`` file."""
        return load(self.binary if form == "binary" else self.json)


@dataclass(frozen=True)
class TrackEntry:
    """A finger track CSV."""

    name: str
    csv: Path
    speed_class: str
    tags: tuple[str, ...]
    description: str = ""

    def load_track(self) -> FingerTrack:
        """The track read from its CSV."""
        return read_track_csv(self.csv)


@dataclass(frozen=True)
class RenderEntry:
    """A golden render of one card along one track, with its options and tolerances."""

    card: str
    track: str
    npz: Path
    frame_rate_hz: float
    band_limit_hz: float
    dead_reckoning_s: float
    mode: str
    tolerance: dict[str, float]
    frames: int

    @property
    def name(self) -> str:
        """``card@track``, the case name of reports."""
        return f"{self.card}@{self.track}"

    def options(self) -> RenderOptions:
        """The render options the golden render was made with."""
        return RenderOptions(
            frame_rate_hz=self.frame_rate_hz,
            band_limit_hz=self.band_limit_hz,
            dead_reckoning_s=self.dead_reckoning_s,
            mode=RenderMode(self.mode),
        )

    def load_arrays(self) -> dict[str, np.ndarray]:
        """The arrays ``t_s, uv, ev, friction`` (float64), ``contact`` (bool), ``texture``."""
        with np.load(self.npz, allow_pickle=False) as data:
            return {name: data[name] for name in RENDER_ARRAYS}


@dataclass(frozen=True)
class InvalidEntry:
    """An invalid card with the error fragment and field path the reference reader reports."""

    name: str
    file: Path
    error: str
    field: str
    rule: str

    def read_bytes(self) -> bytes:
        """The raw file bytes (``read_card_file`` refuses nothing but size and access)."""
        return read_card_file(self.file)

    def parse(self) -> pb.Card:
        """Parse and validate; raises :class:`hcard.errors.CardError` for every entry."""
        return parse_card(self.read_bytes(), source=self.file)


@dataclass(frozen=True)
class CompatEntry:
    """A compatibility vector (README V3, V4, F4): a file that must read as vector card
    ``card`` with minor version ``minor``.

    Attributes:
        name: ``unknown-fields``, ``binary-named`` or ``json-named``.
        file: its path; the suffix is part of the vector (F4 gives a wrong one on purpose).
        form: ``binary`` or ``json``, the form of its content.
        unknown: the fields 1.0 does not define that a re-written binary file must keep (V3),
            each ``{"path", "number", "wire_type", "payload_hex"}``.
    """

    name: str
    file: Path
    form: str
    card: str
    minor: int
    rule: str
    description: str
    unknown: tuple[dict[str, Any], ...] = ()

    @property
    def case(self) -> str:
        """The file's name (``binary-named.json``), the case name of ``format.compat``."""
        return self.file.name


@dataclass(frozen=True)
class Manifest:
    """The whole manifest: cards, tracks, renders, invalid cards and default tolerances."""

    root: Path
    cards: tuple[CardEntry, ...]
    tracks: tuple[TrackEntry, ...]
    renders: tuple[RenderEntry, ...]
    invalid: tuple[InvalidEntry, ...]
    tolerances: dict[str, float] = field(default_factory=dict)
    compat: tuple[CompatEntry, ...] = ()

    def card(self, name: str) -> CardEntry:
        """The card entry called ``name``; KeyError when absent."""
        for entry in self.cards:
            if entry.name == name:
                return entry
        raise KeyError(f"no vector card {name!r}")

    def track(self, name: str) -> TrackEntry:
        """The track entry called ``name``; KeyError when absent."""
        for entry in self.tracks:
            if entry.name == name:
                return entry
        raise KeyError(f"no vector track {name!r}")



def load_manifest(root: str | Path | None = None) -> Manifest:
    """Read ``manifest.json`` of ``root`` (default: :func:`default_root`)."""
    base = Path(root) if root is not None else default_root()
    raw: dict[str, Any] = json.loads((base / MANIFEST_NAME).read_text(encoding="utf-8"))
    if raw.get("format") != MANIFEST_FORMAT:
        raise ValueError(f"{base / MANIFEST_NAME}: format is {raw.get('format')!r}, "
                         f"expected {MANIFEST_FORMAT!r}")
    return Manifest(
        root=base,
        cards=tuple(
            CardEntry(c["name"], base / c["binary"], base / c["json"], tuple(c["tags"]),
                      c.get("description", ""))
            for c in raw["cards"]
        ),
        tracks=tuple(
            TrackEntry(t["name"], base / t["csv"], t["speed_class"], tuple(t["tags"]),
                       t.get("description", ""))
            for t in raw["tracks"]
        ),
        renders=tuple(
            RenderEntry(
                card=r["card"],
                track=r["track"],
                npz=base / r["npz"],
                frame_rate_hz=float(r["frame_rate_hz"]),
                band_limit_hz=float(r["band_limit_hz"]),
                dead_reckoning_s=float(r["dead_reckoning_s"]),
                mode=r["mode"],
                tolerance={k: float(v) for k, v in r["tolerance"].items()},
                frames=int(r["frames"]),
            )
            for r in raw["renders"]
        ),
        invalid=tuple(
            InvalidEntry(i["name"], base / i["file"], i["error"], i["field"], i["rule"])
            for i in raw["invalid"]
        ),
        tolerances={k: float(v) for k, v in raw["tolerances"].items()},
        compat=tuple(
            CompatEntry(c["name"], base / c["file"], c["form"], c["card"], int(c["minor"]),
                        c["rule"], c.get("description", ""), tuple(c.get("unknown", ())))
            for c in raw.get("compat", ())
        ),
    )
