"""The text of ``spec/vectors/README.md`` (generated with the vectors, so ``--check`` covers it)."""

README_TEXT = """\
# hcard conformance vectors

Generated files: do not edit by hand. They are produced by

    python -m hcard_conformance.vectors            # regenerate into spec/vectors
    python -m hcard_conformance.vectors --check    # exit 1 if the files differ from a fresh run

(source: `conformance/hcard_conformance/vectors/`). Generation is deterministic: fixed seeds,
deterministic protobuf serialisation, shortest round-trip floats, NPZ members with fixed
timestamps; two runs give identical bytes, and the project's tests fail when the committed files
drift from the generator. How the vectors are used, every metric and every threshold:
[`../conformance.md`](../conformance.md).

## Files

- `manifest.json`: index of everything below, with tags, options and tolerances (JSON, format
  `hcard-vectors/1`).
- `cards/NAME.hcard`, `cards/NAME.json`: valid cards, the same card in both forms: binary
  protobuf `hcard.v1.Card` and its JSON mapping (README section 8).
- `tracks/NAME.csv`: finger tracks, 50 Hz touch samples (track CSV, `../track-format.md`
  section 1).
- `renders/CARD__TRACK.npz`: golden renders by the reference renderer (NPZ with `t_s, uv, ev,
  friction` float64, `contact` bool, `texture` int32; `../track-format.md` TO2).
- `invalid/NAME.hcard`, `invalid/NAME.json`: invalid cards, one broken rule each.
- `compat/*`: valid files a 1.0 reader meets in the world, each the content of one card
  (README V3, V4, F4): a later minor's binary card and JSON card with fields 1.0 does not
  define, and the two forms under each other's file names.

## Manifest

    {"format": "hcard-vectors/1", "generator": "python -m hcard_conformance.vectors",
     "cards":   [{"name", "binary", "json", "tags", "description"}],
     "tracks":  [{"name", "csv", "speed_class", "tags", "description", "samples", "duration_s"}],
     "renders": [{"card", "track", "npz", "frames", "frame_rate_hz", "band_limit_hz",
                  "dead_reckoning_s", "mode", "tolerance": {"friction_abs", "time_abs_s"}}],
     "invalid": [{"name", "file", "error", "field", "rule"}],
     "compat":  [{"name", "file", "form", "card", "minor", "rule", "description",
                  "unknown": [{"path", "number", "wire_type", "payload_hex"}]}],
     "tolerances": {...}}

Paths are relative to this folder. Card tags (`../conformance.md` Q6): `dense`, `coarse`,
`sparse`, `bipolar`, `temporal`, `oriented`, `checkerboard`. Track speed classes (thesis 5.4):
`slow` (< 30 mm/s), `moderate` (30-180 mm/s), `fast` (> 180 mm/s), by the median speed between
consecutive in-contact samples. `tolerances` holds the default thresholds and constants of
`../conformance.md` section 0.

Golden renders use the defaults of README R1 (hybrid mode, `fs` = 10 kHz, `B` = 1000 Hz,
`H` = 0.1 s); every entry states them.

## Using the vectors from any language

1. **Reader** (README 1.2, `../conformance.md` Q2-Q4): parse every `cards/*.hcard` and
   `cards/*.json` with the `hcard.v1.Card` code generated from `../hcard/v1/card.proto`
   (README section 9), validate, and check that re-serialising gives the other file's content
   (deterministic binary; JSON compared as parsed messages if your JSON writer differs from the
   reference one). Every `invalid/*` file must be rejected; the manifest gives the field path
   your error should name and a fragment of the reference message. Every `compat/*` file
   must read as its `card` with version minor `minor` (`../conformance.md` Q4b); re-written as
   binary, `compat/unknown-fields.hcard` must keep each field of its `unknown` list (README
   V3: the message at `path` holds field `number` of `wire_type` with the bytes `payload_hex`
   after its tag).
2. **Renderer** (README R13, `../conformance.md` A0): for every `renders` entry, read the card and
   the track CSV, render with the stated options, and compare with the NPZ: same frame count,
   `t_s` within 1e-9 s, `uv`, `ev`, `friction` within `tolerance.friction_abs` (1e-5),
   identical `contact` and `texture`. An NPZ is a zip of `.npy` files: NumPy reads it with
   `numpy.load`; elsewhere unzip it and read each `.npy` (a short header then raw
   little-endian data: `<f8`, `|b1`, `<i4`), e.g. with `cnpy` (C++), `npyz` (Rust) or
   `org.jetbrains.bio:npy` (JVM).
3. **Device**: run `hcard conformance --driver YOUR_DRIVER`; the device level plays these cards
   and tracks through your driver plugin (`../../conformance/README.md`).

With the Python reference implementation:

    from hcard_conformance.vectors import load_manifest
    manifest = load_manifest()                 # spec/vectors of the repository
    entry = manifest.renders[0]
    card = manifest.card(entry.card).load_card()
    track = manifest.track(entry.track).load_track()
    golden = entry.load_arrays()               # dict of the six arrays
"""
