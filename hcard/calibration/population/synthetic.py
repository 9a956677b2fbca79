"""Synthetic population studies, independent of the fitting code: each participant's recording
is the forward model of thesis Eqs. 2.30 and 2.33 (``Psi = U / (w f mu0 (1 + nu))``,
``F_l = mu0 Fn (1 - exp(-Psi / Psi*))``) evaluated with numpy plus white sensor noise, with
``Psi*`` and ``mu0`` of each participant drawn from a known normal population (Fig. 2.38 shows
two participants' Psi* of 1.89 +- 0.18 and 0.78 +- 0.046: participants differ). Only numpy and
the file format (CSV with a JSON sidecar, spec/measurement-format.md) are used, so the tests
and benches that fit these studies check the fit against an outside truth.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

NU, F_PLATE = 0.33, 27_500.0
PSI_MEAN, PSI_SPREAD = 1.3, 0.2
MU0_MEAN, MU0_SPREAD = 0.5, 0.08
ODD = 3
"""The participant whose friction has a load index n = 0.5 (Eq. 2.35), the others n = 1."""


def write_recording(path: Path, participant: str | None, psi_star: float, mu0: float,
                    noise: float, rng: np.random.Generator, load_index: float = 1.0,
                    strokes: int = 12) -> None:
    """One participant's recording: strokes of 0.4 s at 100 Hz over speeds 20-80 mm/s,
    amplitudes 0-4 um and forces 0.3-1.2 N, lifts of 0.3 s between (forward model in the
    module docstring, noise N(0, noise^2) in N on the lateral force)."""
    speeds, amps, forces = [0.02, 0.04, 0.08], [0.0, 1e-6, 2e-6, 4e-6], [0.3, 0.7, 1.2]
    rows, t = [], 0.0
    for k in range(strokes):
        u = speeds[k % 3] * (1 if k % 2 == 0 else -1)
        w, fn = amps[(k // 3) % 4], forces[(k // 2) % 3]
        psi = abs(u) / (w * F_PLATE * mu0 * (1 + NU)) if w > 0 else math.inf
        force = mu0 * fn * (1 - math.exp(-psi / psi_star)) * fn ** (load_index - 1)
        for _ in range(40):
            rows.append((t, fn, math.copysign(force, u) + rng.normal(0, noise), w, u))
            t += 0.01
        for _ in range(30):
            rows.append((t, 0.0, rng.normal(0, noise), 0.0, 0.0))
            t += 0.01
    lines = ["t_s,fn_n,fl_n,amplitude_m,speed_m_s"]
    lines += [",".join(repr(float(x)) for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    side: dict[str, object] = {"device": "tribometer", "plate_frequency_hz": F_PLATE}
    if participant is not None:
        side["participant"] = participant
    Path(f"{path}.json").write_text(json.dumps(side))


def make_study(folder: Path, n: int, seed: int) -> np.ndarray:
    """``n`` participants' recordings in ``folder``; returns their true (psi_star, mu0)."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    psi = rng.normal(PSI_MEAN, PSI_SPREAD, n)
    mu0 = rng.normal(MU0_MEAN, MU0_SPREAD, n)
    noise = rng.uniform(0.01, 0.05, n)
    for i in range(n):
        write_recording(folder / f"p{i:03d}.csv", f"p{i:03d}", psi[i], mu0[i], noise[i], rng,
                        load_index=0.5 if i == ODD else 1.0)
    return np.stack([psi, mu0])
