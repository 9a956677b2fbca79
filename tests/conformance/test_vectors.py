"""The conformance vectors of spec/vectors: deterministic, complete, and consistent with hcard."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from hcard import card_io
from hcard.errors import CardError
from hcard.render import Renderer
from hcard.validate import errors_of, validate
from hcard_conformance.vectors import (
    CardEntry,
    InvalidEntry,
    RenderEntry,
    TrackEntry,
    generate,
    load_manifest,
)
from hcard_conformance.vectors.__main__ import main
from hcard_conformance.vectors.generate import differences, generated_files

REPO = Path(__file__).resolve().parents[2]
ROOT = REPO / "spec" / "vectors"
MANIFEST = load_manifest(ROOT)


def _tree(root: Path) -> dict[str, bytes]:
    return {
        path.relative_to(root).as_posix(): path.read_bytes()
        for path in sorted(root.rglob("*"))
        if path.is_file()
    }


def test_generation_is_deterministic_and_matches_the_committed_files(tmp_path: Path) -> None:
    first, second = tmp_path / "a", tmp_path / "b"
    generate(first)
    generate(second)
    tree_a, tree_b = _tree(first), _tree(second)
    # README, manifest, 12 cards x 2 forms, 9 tracks, 28 renders, 26 invalid cards, 4 compat
    assert len(tree_a) == 93
    assert tree_a == tree_b
    assert tree_a == _tree(ROOT)
    assert differences(ROOT) == []


def test_check_mode_fails_on_drift_and_passes_when_fresh(tmp_path: Path) -> None:
    out = tmp_path / "vectors"
    shutil.copytree(ROOT, out)
    assert main(["--out", str(out), "--check"]) == 0
    track = out / "tracks" / "slow-stroke.csv"
    track.write_bytes(track.read_bytes().replace(b"45.0", b"45.5", 1))
    (out / "cards" / "stale.hcard").write_bytes(b"\x08\x01")
    assert main(["--out", str(out), "--check"]) == 1
    assert sorted(differences(out)) == [
        "differs: tracks/slow-stroke.csv",
        "extra: cards/stale.hcard",
    ]
    assert main(["--out", str(out)]) == 0
    assert differences(out) == []
    assert not (out / "cards" / "stale.hcard").exists()


def test_manifest_covers_every_required_kind_of_vector() -> None:
    assert (len(MANIFEST.cards), len(MANIFEST.tracks)) == (12, 9)
    assert (len(MANIFEST.renders), len(MANIFEST.invalid)) == (28, 26)
    tags = {tag for card in MANIFEST.cards for tag in card.tags}
    assert tags == {"dense", "coarse", "sparse", "bipolar", "temporal", "oriented",
                    "checkerboard"}
    assert {t.speed_class for t in MANIFEST.tracks} == {"slow", "moderate", "fast"}
    track_tags = {tag for t in MANIFEST.tracks for tag in t.tags}
    assert {"reversal", "liftoff", "touchdown"} <= track_tags
    names = {card.name for card in MANIFEST.cards}
    for render in MANIFEST.renders:
        assert render.card in names
        assert MANIFEST.track(render.track).csv.is_file()
        assert render.tolerance == {"friction_abs": 1e-5, "time_abs_s": 1e-9}
        assert (render.frame_rate_hz, render.band_limit_hz, render.mode) == (
            10_000.0, 1_000.0, "hybrid")
    rendered_tags = {tag for r in MANIFEST.renders for tag in MANIFEST.card(r.card).tags}
    assert rendered_tags == tags
    assert {r.track for r in MANIFEST.renders} == {t.name for t in MANIFEST.tracks}
    assert {i.name for i in MANIFEST.invalid} >= {
        "truncated", "corrupt", "wrong-major", "nan-amplitude", "infinite-baseline",
        "zero-frequency", "negative-frequency", "too-many-components", "grid-size-mismatch",
        "index-outside-palette", "missing-channel", "uv-baseline-above-1",
    }
    assert MANIFEST.tolerances["friction_rel_jnd"] == 0.08
    assert MANIFEST.tolerances["rise_time_s"] == 0.002
    assert MANIFEST.tolerances["bandwidth_hz"] == 400.0


def test_vectors_stay_small() -> None:
    total = sum(len(data) for data in generated_files().values())
    assert total == sum(len(data) for data in _tree(ROOT).values())
    assert total < 5_000_000
    for render in MANIFEST.renders:
        assert render.npz.stat().st_size < 200_000


@pytest.mark.parametrize("entry", MANIFEST.cards, ids=lambda e: e.name)
def test_valid_card_validates_and_round_trips_bit_exactly(entry: CardEntry) -> None:
    binary = entry.binary.read_bytes()
    text = entry.json.read_bytes()
    from_binary = card_io.parse_card(binary)
    from_json = card_io.parse_card(text)
    assert errors_of(validate(from_binary)) == []
    assert from_binary == from_json
    assert card_io.to_bytes(from_json) == binary
    assert card_io.dumps(from_binary, "json") == text
    assert card_io.to_bytes(card_io.parse_card(card_io.dumps(from_binary, "json"))) == binary
    assert entry.load_card("json") == entry.load_card("binary")


@pytest.mark.parametrize("entry", MANIFEST.invalid, ids=lambda e: e.name)
def test_invalid_card_is_rejected_with_its_documented_error(entry: InvalidEntry) -> None:
    assert entry.error
    with pytest.raises(CardError) as caught:
        entry.parse()
    assert entry.error in caught.value.reason
    assert caught.value.field_path == entry.field
    with pytest.raises(CardError):
        card_io.load(entry.file)


@pytest.mark.parametrize("entry", MANIFEST.renders, ids=lambda e: e.name)
def test_golden_render_equals_a_fresh_rendering(entry: RenderEntry) -> None:
    golden = entry.load_arrays()
    assert golden["t_s"].dtype == np.float64 and golden["friction"].dtype == np.float64
    assert golden["contact"].dtype == np.bool_ and golden["texture"].dtype == np.int32
    card = MANIFEST.card(entry.card).load_card()
    track = MANIFEST.track(entry.track).load_track()
    frames = Renderer(card, entry.options()).render(track)
    assert len(frames) == entry.frames == golden["t_s"].shape[0]
    assert np.max(np.abs(frames.t - golden["t_s"])) <= entry.tolerance["time_abs_s"]
    tol = entry.tolerance["friction_abs"]
    for name, fresh in (("uv", frames.uv), ("ev", frames.ev), ("friction", frames.friction)):
        assert np.max(np.abs(fresh - golden[name])) <= tol, name
    assert np.array_equal(frames.contact, golden["contact"])
    assert np.array_equal(frames.texture, golden["texture"])
    assert np.all((golden["uv"] >= 0) & (golden["uv"] <= 1))
    assert np.all((golden["ev"] >= 1) & (golden["ev"] <= 4))
    assert golden["contact"].any()


def test_golden_renders_exercise_what_their_tags_claim() -> None:
    arrays = {r.name: r.load_arrays() for r in MANIFEST.renders}
    assert np.ptp(arrays["bipolar-extreme@moderate-stroke"]["friction"]) > 3.9
    bipolar = arrays["bipolar-grating@moderate-stroke"]
    assert bipolar["uv"].min() < 0.45 and bipolar["ev"].max() > 1.55
    edge = arrays["edge@reversal"]["texture"]
    assert int(np.count_nonzero(np.diff(edge) != 0)) == 3
    checker = arrays["checkerboard-three@moderate-stroke"]["texture"]
    assert set(np.unique(checker)) == {0, 1, 2}
    lift = arrays["temporal@liftoff"]
    assert not lift["contact"].all() and lift["contact"][0] and lift["contact"][-1]
    button = arrays["button@moderate-stroke"]["texture"]
    assert set(np.unique(button)) == {0, 1, 2}
    oriented = arrays["oriented-gratings@diagonal-stroke"]["texture"]
    assert len(set(np.unique(oriented))) >= 3


@pytest.mark.parametrize("entry", MANIFEST.tracks, ids=lambda e: e.name)
def test_track_speed_class_holds(entry: TrackEntry) -> None:
    track = entry.load_track()
    assert track.duration_s <= 1.2 + 1e-9
    steps = np.diff(track.t)
    assert np.all(np.abs(steps - 0.02) <= 0.002 + 1e-12)  # 50 Hz touch, +-1 ms jitter at most
    both = track.contact[1:] & track.contact[:-1]
    speed = (np.hypot(np.diff(track.x), np.diff(track.y)) / steps)[both]
    median = float(np.median(speed))
    if entry.speed_class == "slow":
        assert median < 30.0 and speed.max() < 30.0
    elif entry.speed_class == "fast":
        assert median > 180.0 and speed.min() > 180.0
    else:
        assert entry.speed_class == "moderate"
        assert speed.min() >= 30.0 and speed.max() <= 180.0


def test_reversal_and_liftoff_tracks_do_what_they_say() -> None:
    reversal = MANIFEST.track("reversal").load_track()
    vx = np.diff(reversal.x)
    assert int(np.count_nonzero(np.diff(np.sign(vx)) != 0)) == 2
    liftoff = MANIFEST.track("liftoff").load_track()
    changes = np.flatnonzero(np.diff(liftoff.contact.astype(int)))
    assert liftoff.contact[0] and liftoff.contact[-1]
    assert changes.tolist() == [25, 34]  # lift-off after 0.50 s, touch-down at 0.70 s
    assert liftoff.x[35] - liftoff.x[25] == pytest.approx(30.0)  # touch-down 30 mm on
