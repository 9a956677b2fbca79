"""Fetch the public asset files the interchange tests read but the repository may not include.

Their projects publish them without a licence that allows redistribution (TanvasProject,
DrivingStudy-TanvasTouch, TPadSoftware and data-driven-playback-of-natural-tactile-texture
state none; the Interhaptics SDK's files are "all
rights reserved" under its EULA), so they are not in ``tests/data/public/``: this script brings
them into ``tests/data/public/fetched/<owner>+<repo>/<path>`` (git-ignored), and the tests that
read them skip, saying so, when they are absent. Every file is pinned to a commit and a
SHA-256, so a test reads exactly the bytes its figures were measured on.

Run from the repository root, with internet access::

    python scripts/fetch_public_samples.py            # from raw.githubusercontent.com
    python scripts/fetch_public_samples.py --mirror DIR
                                   # from local bare snapshots <owner>+<repo>/repo (git show)
    python scripts/fetch_public_samples.py --list     # what it would fetch, and what is here

Exit status 0 when every file is present and matches its hash afterwards, 1 otherwise.
"""

from __future__ import annotations

import argparse
import hashlib
import subprocess
import sys
import urllib.request
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FETCHED = REPO / "tests" / "data" / "public" / "fetched"
"""Where fetched files go (``.gitignore`` keeps them out of the repository)."""
RAW_URL = "https://raw.githubusercontent.com/{repo}/{commit}/{path}"
TIMEOUT_S = 60.0


@dataclass(frozen=True)
class Sample:
    """One public file: its repository (``owner/name``), commit, path and SHA-256."""

    repo: str
    commit: str
    path: str
    sha256: str

    @property
    def local(self) -> Path:
        """Where the tests find it."""
        return FETCHED / self.repo.replace("/", "+") / self.path


TANVAS = ("CaritaRoti/TanvasProject", "3d630ee59e776adf38687682e58a1aa307ca197d")
KNOB = ("brockel27/DrivingStudy-TanvasTouch", "18a0b933ea3fd04d0566aedcf88edd4e7e5f85ad")
TPAD = ("TPadTabletProject/TPadSoftware", "6e169106fdacee4fa300240ad0ec7d7d3d3e6016")
INTERHAPTICS = ("Interhaptics/Unity_CoreSDK", "3f1f9144d7c8c27f4d958020e7c1e8670bcbd120")
GRIGORII = ("romangrigorii/data-driven-playback-of-natural-tactile-texture",
            "58cd7fcdec94f82f504bb17b2e547ee64c70bde9")
"""A real finger-on-glass tribometer recording (Northwestern, 10 kHz, NI-DAQ ``dataQ`` of
lateral force, normal force, vibrometer, EA current monitor, encoder); no licence stated.
Read by examples/public_data/grigorii-tribometer/ and tests/calibration/test_public_data.py."""

SAMPLES: tuple[Sample, ...] = ()
"""Filled in below from :data:`_TABLE` (repository, path, SHA-256)."""
_TABLE = (
    (TANVAS, "TanvasProject/Assets/HelloTanvas_haptics.png",
     "0915e43bbdb24ee298a53438284c2cae0fa21896a56144dbc99a9aff063b4d0b"),
    (TANVAS, "TanvasProject/Assets/appHapticSprite.png",
     "f10669b6abfb67250bb9defc85b9c106ea4ab346dbcae9a77e974236df71c572"),
    (KNOB, "tanvas_knob/assets/nub/haptics@1.png",
     "2170a31c77c183083ab98bfc4c969a079201d583fa6fb707ca4678d159b75f1e"),
    (KNOB, "tanvas_knob/assets/background/rotation_haptics@1.png",
     "d975551206f236b14173257443e587a675215acfe259a2a398714aae23d66f68"),
    (TPAD, "HelloTPadPhone/res/drawable/spacialgrad.png",
     "46cd8e1aed8739e851a72926b2cad04e9c84c599b47c84248bf6c8adee410a01"),
    (TPAD, "HelloTPadPhone/res/drawable/testdepth.png",
     "9b1c34528906a0bbe62908034342476ecc06c090b4b10fe3eff0d62a47f1c130"),
    (TPAD, "HelloTPadPhone/res/drawable/testdepthbars.png",
     "142b69f8f3a7932c0162aa1c26528287a6c9f14a8e89f7fa26fe3b994e9eaee7"),
    (INTERHAPTICS, "Assets/HapticEffects/Texture.haps",
     "3b6a93e0e781703b25ecec2acdbdf755d6439adc929fdd7733a6126a2d77dcb0"),
    (INTERHAPTICS, "Assets/HapticEffects/Stiffness.haps",
     "ce795d8066e3913fb7faf0ef3143b3d0de63760d4c3910744672e6d306eb7fd9"),
    (INTERHAPTICS, "Assets/HapticEffects/Swipe_Freq10.haps",
     "941bb9e8487b360335a0285435bdd0cdc4d710ed09dcdec2c78f78f310515812"),
    (INTERHAPTICS, "Assets/HapticEffects/Swipe_Amplitude10.haps",
     "941bb9e8487b360335a0285435bdd0cdc4d710ed09dcdec2c78f78f310515812"),
    (GRIGORII, "matlab/DAQ/data/data_temp.mat",
     "38083f173ecfc7bc98fd96e48451f8c27cf49dd32989ff63daedc2d7e0785248"),
)
SAMPLES = tuple(Sample(repo, commit, path, digest) for (repo, commit), path, digest in _TABLE)


def sample_path(repo: str, path: str) -> Path:
    """Where a test finds the public file ``path`` of ``repo`` (present or not)."""
    return FETCHED / repo.replace("/", "+") / path


def _from_mirror(mirror: Path, sample: Sample) -> bytes:
    git_dir = mirror / sample.repo.replace("/", "+") / "repo"
    done = subprocess.run(["git", "--git-dir", str(git_dir), "show",
                           f"{sample.commit}:{sample.path}"], capture_output=True, check=False)
    if done.returncode:
        raise OSError(done.stderr.decode(errors="replace").strip() or "git show failed")
    return done.stdout


def _from_github(sample: Sample) -> bytes:
    url = RAW_URL.format(repo=sample.repo, commit=sample.commit, path=sample.path)
    with urllib.request.urlopen(url, timeout=TIMEOUT_S) as response:
        data: bytes = response.read()
    return data


def _matches(sample: Sample, data: bytes) -> bool:
    return not sample.sha256 or hashlib.sha256(data).hexdigest() == sample.sha256


def main(argv: list[str] | None = None) -> int:
    """Fetch what is missing; 0 when every sample is present and intact afterwards."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mirror", type=Path, help="directory of bare snapshots "
                        "<owner>+<repo>/repo to read instead of GitHub")
    parser.add_argument("--list", action="store_true", help="list the samples and stop")
    args = parser.parse_args(argv)
    missing = 0
    for sample in SAMPLES:
        here = sample.local.is_file() and _matches(sample, sample.local.read_bytes())
        if args.list:
            print(f"{'present' if here else 'absent '}  {sample.repo}@{sample.commit[:7]}  "
                  f"{sample.path}")
            continue
        if here:
            continue
        try:
            data = (_from_mirror(args.mirror, sample) if args.mirror
                    else _from_github(sample))
        except OSError as exc:
            print(f"not fetched: {sample.repo} {sample.path}: {exc}", file=sys.stderr)
            missing += 1
            continue
        if not _matches(sample, data):
            print(f"not kept: {sample.repo} {sample.path}: SHA-256 "
                  f"{hashlib.sha256(data).hexdigest()} is not the pinned {sample.sha256}",
                  file=sys.stderr)
            missing += 1
            continue
        sample.local.parent.mkdir(parents=True, exist_ok=True)
        sample.local.write_bytes(data)
        print(f"fetched {sample.local.relative_to(REPO)} ({len(data)} bytes)")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
