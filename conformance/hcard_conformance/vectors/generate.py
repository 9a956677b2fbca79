"""Deterministic generation of ``spec/vectors``: the same bytes on every run and machine.

Cards are serialised with deterministic protobuf and the reference JSON writer, tracks with
shortest round-trip floats, golden renders as NPZ archives written with fixed zip timestamps
(``numpy.savez`` stamps the current time, so it is not used).
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np

from hcard import card_io
from hcard.rates import DEFAULT_FRAME_RATE_HZ
from hcard.render import Frames, Renderer, RenderOptions
from hcard.track import track_to_csv
from hcard_conformance.vectors.cards import vector_cards
from hcard_conformance.vectors.compat import compat_vectors
from hcard_conformance.vectors.invalid import invalid_vectors
from hcard_conformance.vectors.manifest import MANIFEST_FORMAT, MANIFEST_NAME
from hcard_conformance.vectors.readme import README_TEXT
from hcard_conformance.vectors.tracks import vector_tracks

GENERATOR = "python -m hcard_conformance.vectors"
ZIP_TIME = (1980, 1, 1, 0, 0, 0)
"""Timestamp of every NPZ member (the zip epoch), for byte-identical archives."""
SUBDIRS = ("cards", "tracks", "renders", "invalid", "compat")

RENDER_PAIRS: tuple[tuple[str, str], ...] = (
    ("single-grating", "slow-stroke"),
    ("single-grating", "moderate-stroke"),
    ("single-grating", "fast-stroke"),
    ("single-grating", "reversal"),
    ("single-grating", "liftoff"),
    ("single-grating", "noisy-stroke"),
    ("single-grating", "flick"),
    ("single-grating-auto", "moderate-stroke"),
    ("oriented-gratings", "diagonal-stroke"),
    ("oriented-gratings", "moderate-stroke"),
    ("checkerboard", "slow-stroke"),
    ("checkerboard", "moderate-stroke"),
    ("checkerboard-three", "moderate-stroke"),
    ("edge", "slow-stroke"),
    ("edge", "moderate-stroke"),
    ("edge", "fast-stroke"),
    ("edge", "reversal"),
    ("button", "moderate-stroke"),
    ("button", "diagonal-stroke"),
    ("bipolar-grating", "moderate-stroke"),
    ("bipolar-grating", "fast-stroke"),
    ("bipolar-extreme", "moderate-stroke"),
    ("temporal", "slow-stroke"),
    ("temporal", "liftoff"),
    ("coarse-grating", "slow-stroke"),
    ("coarse-grating", "moderate-stroke"),
    ("coarse-grating", "fast-stroke"),
    ("coarse-grating", "scrub"),
)
"""The (card, track) pairs with a golden render."""

RENDER_TOLERANCE = {"friction_abs": 1e-5, "time_abs_s": 1e-9}
"""Per-render exact tolerance (README R13; spec/conformance.md A0)."""

TOLERANCES: dict[str, float] = {
    "friction_abs": 1e-5,
    "time_abs_s": 1e-9,
    "friction_rel_jnd": 0.08,
    "component_amplitude_rel": 0.08,
    "component_frequency_rel": 0.05,
    "spatial_phase_mm": 2.5,
    "boundary_mm": 2.5,
    "bandwidth_hz": 400.0,
    "rise_time_s": 0.002,
    "latency_s": 0.010,
    "fault_reaction_s": 0.010,
    "safety_violations": 0.0,
    "frame_rate_hz": DEFAULT_FRAME_RATE_HZ,
    "guard_s": 0.020,
    "relative_floor": 0.1,
    "peak_min_amplitude": 0.02,
    "segment_min_s": 0.2,
    "correlation_window_s": 0.050,
    "speed_min_mm_s": 5.0,
}
"""Default thresholds and constants of spec/conformance.md section 0."""


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """A compressed NPZ archive of ``arrays`` (in the given order) with fixed timestamps."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, value in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.ascontiguousarray(value), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, member.getvalue(), compresslevel=9)
    return buffer.getvalue()


def frames_arrays(frames: Frames) -> dict[str, np.ndarray]:
    """The six arrays of a render file (spec/track-format.md TO2), as ``hcard render`` writes."""
    return {
        "t_s": frames.t.astype(np.float64),
        "uv": frames.uv.astype(np.float64),
        "ev": frames.ev.astype(np.float64),
        "friction": frames.friction.astype(np.float64),
        "contact": frames.contact.astype(bool),
        "texture": frames.texture.astype(np.int32),
    }


def _json_bytes(obj: object) -> bytes:
    return (json.dumps(obj, indent=2, sort_keys=False) + "\n").encode("utf-8")


def generated_files() -> dict[str, bytes]:
    """Every file of the vectors directory: relative path (``/``-separated) to bytes."""
    files: dict[str, bytes] = {}
    options = RenderOptions()
    cards = {vc.name: vc for vc in vector_cards()}
    tracks = {vt.name: vt for vt in vector_tracks()}
    manifest: dict[str, object] = {"format": MANIFEST_FORMAT, "generator": GENERATOR}

    card_rows = []
    for vc in cards.values():
        binary, text = f"cards/{vc.name}.hcard", f"cards/{vc.name}.json"
        files[binary] = card_io.to_bytes(vc.card)
        files[text] = card_io.to_json(vc.card).encode("utf-8")
        card_rows.append({"name": vc.name, "binary": binary, "json": text, "tags": list(vc.tags),
                          "description": vc.card.metadata.description})
    manifest["cards"] = card_rows

    track_rows = []
    for vt in tracks.values():
        path = f"tracks/{vt.name}.csv"
        header = (
            f"# hcard conformance vector track {vt.name} ({vt.speed_class}): {vt.description}\n"
        )
        files[path] = (header + track_to_csv(vt.track)).encode("utf-8")
        track_rows.append({"name": vt.name, "csv": path, "speed_class": vt.speed_class,
                           "tags": list(vt.tags), "description": vt.description,
                           "samples": len(vt.track),
                           "duration_s": vt.track.duration_s})
    manifest["tracks"] = track_rows

    render_rows = []
    renderers = {name: Renderer(vc.card, options) for name, vc in cards.items()}
    for card_name, track_name in RENDER_PAIRS:
        frames = renderers[card_name].render(tracks[track_name].track)
        path = f"renders/{card_name}__{track_name}.npz"
        files[path] = npz_bytes(frames_arrays(frames))
        render_rows.append({
            "card": card_name,
            "track": track_name,
            "npz": path,
            "frames": len(frames),
            "frame_rate_hz": options.frame_rate_hz,
            "band_limit_hz": options.band_limit_hz,
            "dead_reckoning_s": options.dead_reckoning_s,
            "mode": options.mode.value,
            "tolerance": dict(RENDER_TOLERANCE),
        })
    manifest["renders"] = render_rows

    invalid_rows = []
    for iv in invalid_vectors():
        path = f"invalid/{iv.name}{iv.extension}"
        files[path] = iv.data
        invalid_rows.append({"name": iv.name, "file": path, "error": iv.error,
                             "field": iv.field, "rule": iv.rule})
    manifest["invalid"] = invalid_rows

    compat_rows = []
    for cv in compat_vectors():
        path = f"compat/{cv.file_name}"
        files[path] = cv.data
        compat_rows.append({"name": cv.name, "file": path,
                            "form": "json" if card_io.looks_like_json(cv.data) else "binary",
                            "card": cv.card, "minor": cv.minor, "rule": cv.rule,
                            "description": cv.description,
                            "unknown": [u.as_json() for u in cv.unknown]})
    manifest["compat"] = compat_rows
    manifest["tolerances"] = dict(TOLERANCES)

    files[MANIFEST_NAME] = _json_bytes(manifest)
    files["README.md"] = README_TEXT.encode("utf-8")
    return dict(sorted(files.items()))


def generate(root: str | Path) -> list[Path]:
    """Write every vector file into ``root``, removing stale files of its subdirectories.

    Returns the paths written. Running it twice gives byte-identical files.
    """
    base = Path(root)
    files = generated_files()
    for sub in SUBDIRS:
        folder = base / sub
        if folder.is_dir():
            for old in folder.iterdir():
                if old.is_file() and f"{sub}/{old.name}" not in files:
                    old.unlink()
    written = []
    for rel, data in files.items():
        path = base / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
        written.append(path)
    return written


def differences(root: str | Path) -> list[str]:
    """Files of ``root`` that differ from a fresh generation: missing, changed or extra."""
    base = Path(root)
    files = generated_files()
    problems = []
    for rel, data in files.items():
        path = base / rel
        if not path.is_file():
            problems.append(f"missing: {rel}")
        elif path.read_bytes() != data:
            problems.append(f"differs: {rel}")
    for sub in SUBDIRS:
        folder = base / sub
        if folder.is_dir():
            for old in sorted(folder.iterdir()):
                if f"{sub}/{old.name}" not in files:
                    problems.append(f"extra: {sub}/{old.name}")
    return problems
