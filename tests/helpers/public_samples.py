"""Public asset files the interchange tests read but the repository does not include (their
licences do not allow it): ``scripts/fetch_public_samples.py`` brings them, pinned by commit and
SHA-256, into ``tests/data/public/fetched/<owner>+<repo>/<path>``; a test that needs one skips,
saying why, when it is absent (CI cannot fetch)."""

from __future__ import annotations

from pathlib import Path

import pytest

FETCHED = Path(__file__).resolve().parents[1] / "data" / "public" / "fetched"
"""Where the fetch script puts the files (git-ignored)."""


def fetched_sample(repo: str, path: str, why_not_included: str) -> Path:
    """The fetched file ``path`` of GitHub repository ``repo`` (``owner/name``); the test skips
    when it is absent, naming the file, the script that brings it and ``why_not_included``."""
    local = FETCHED / repo.replace("/", "+") / path
    if not local.is_file():
        pytest.skip(f"{repo} {path} not fetched ({why_not_included}): run "
                    "python scripts/fetch_public_samples.py")
    return local
