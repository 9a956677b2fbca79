"""Conformance test vectors: cards, finger tracks, golden renders and invalid cards.

``generate(root)`` writes them deterministically into ``root`` (normally ``spec/vectors``);
``load_manifest(root)`` reads them back as typed entries. Run ``python -m
hcard_conformance.vectors [--out DIR] [--check]`` to regenerate or verify the committed files.
"""

from hcard_conformance.vectors.generate import generate, generated_files
from hcard_conformance.vectors.manifest import (
    MANIFEST_FORMAT,
    CardEntry,
    InvalidEntry,
    Manifest,
    RenderEntry,
    TrackEntry,
    default_root,
    load_manifest,
)

__all__ = [
    "MANIFEST_FORMAT",
    "CardEntry",
    "InvalidEntry",
    "Manifest",
    "RenderEntry",
    "TrackEntry",
    "default_root",
    "generate",
    "generated_files",
    "load_manifest",
]
