"""An independent double-precision rendering, written from the reference pseudocode of
spec/README.md section 6.6 (rules R3-R11), frame by frame and component by component: no code
of hcard.render, float64 throughout (the cosine too). Slow; for checking the renderer's
numbers on short tracks or on chosen frames of long ones."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hcard.v1 import card_pb2 as pb

AUTO_PERIOD_MM = 10.0
"""P_auto (R1, R8)."""


@dataclass(frozen=True)
class Reference:
    """Frames of the reference rendering: times (s), UV and EV targets, palette index."""

    t: np.ndarray
    uv: np.ndarray
    ev: np.ndarray
    texture: np.ndarray


def sample_states(t, x, y, contact, horizon_s: float) -> dict[str, np.ndarray]:
    """R4 for every sample, one after another as in the pseudocode's ``on_sample``."""
    m = len(t)
    out = {name: np.zeros(m) for name in ("vx", "vy", "touchdown_t", "ox", "oy")}
    prev = None
    for i in range(m):
        c = bool(contact[i])
        d = c and (prev is None or not prev["c"])
        if c and not d:
            vx = (x[i] - prev["x"]) / (t[i] - prev["t"])
            vy = (y[i] - prev["y"]) / (t[i] - prev["t"])
        else:
            vx = vy = 0.0
        big_t = t[i] if d or prev is None else prev["T"]
        if not c or d or prev["d"]:
            ox, oy = x[i], y[i]
        else:
            step = min(t[i] - prev["t"], horizon_s)
            ox, oy = prev["ox"] + prev["vx"] * step, prev["oy"] + prev["vy"] * step
        prev = {"t": t[i], "x": x[i], "y": y[i], "c": c, "d": d, "vx": vx, "vy": vy,
                "T": big_t, "ox": ox, "oy": oy}
        for name in out:
            out[name][i] = prev[{"touchdown_t": "T"}.get(name, name)]
    return out


def reference_render(
    card: pb.Card,
    t, x, y, contact,
    *,
    frame_rate_hz: float = 10_000.0,
    band_limit_hz: float = 1_000.0,
    horizon_s: float = 0.1,
    t0: float | None = None,
    frames: np.ndarray | None = None,
) -> Reference:
    """Render ``card`` along the samples ``t, x, y, contact``.

    Args:
        t0: time of frame 0 (default: the first sample, R3).
        frames: frame indices to render (default: every frame of the batch rendering, R3).
    """
    t, x, y = (np.asarray(a, dtype=np.float64) for a in (t, x, y))
    contact = np.asarray(contact, dtype=bool)
    t0 = float(t[0]) if t0 is None else t0
    if frames is None:
        frames = np.arange(math.floor((t[-1] - t0) * frame_rate_hz + 1e-9) + 1)
    tau = t0 + np.asarray(frames, dtype=np.float64) / frame_rate_hz  # R3
    state = sample_states(t, x, y, contact, horizon_s)
    i = np.searchsorted(t, tau, side="right") - 1  # R5
    ok = i >= 0
    i = np.maximum(i, 0)
    ok &= contact[i]
    dt = np.minimum(tau - t[i], horizon_s)  # R6
    vx, vy = state["vx"][i], state["vy"][i]
    px, py = x[i] + vx * dt, y[i] + vy * dt
    qx, qy = state["ox"][i] + vx * dt, state["oy"][i] + vy * dt
    width, height = card.surface.width_mm, card.surface.height_mm  # R7
    ok &= (px >= 0) & (px < width) & (py >= 0) & (py < height)
    grid = card.grid
    col = np.minimum(np.floor(np.where(ok, px, 0) / grid.taxtel_width_mm), grid.cols - 1)
    row = np.minimum(np.floor(np.where(ok, py, 0) / grid.taxtel_height_mm), grid.rows - 1)
    index = np.asarray(grid.texture_index)[(row * grid.cols + col).astype(int)]
    texture = np.where(ok, index, -1)
    groups = {pb.CHANNEL_UV: np.zeros(tau.size), pb.CHANNEL_EV: np.zeros(tau.size),
              pb.CHANNEL_BIPOLAR: np.zeros(tau.size)}
    for k, tex in enumerate(card.textures):
        on = texture == k
        groups[tex.channel][on] += tex.baseline - 1.0
        for comp in tex.components:
            if comp.domain == pb.DOMAIN_SPATIAL:  # R8, R9, R10
                nx, ny = math.cos(comp.orientation), math.sin(comp.orientation)
                lock = tex.locking
                if lock == pb.LOCKING_AUTO:
                    lock = (pb.LOCKING_VELOCITY if 1.0 / comp.frequency < AUTO_PERIOD_MM
                            else pb.LOCKING_POSITION)
                bx, by = (qx, qy) if lock == pb.LOCKING_VELOCITY else (px, py)
                psi = comp.frequency * (nx * bx[on] + ny * by[on]) + comp.phase / (2 * math.pi)
                f = comp.frequency * np.abs(nx * vx[on] + ny * vy[on])
            else:
                psi = comp.frequency * (tau[on] - state["touchdown_t"][i[on]]) \
                    + comp.phase / (2 * math.pi)
                f = np.full(psi.shape, comp.frequency)
            s = np.clip((f - 0.8 * band_limit_hz) / (0.2 * band_limit_hz), 0.0, 1.0)
            gain = 1.0 - s * s * (3.0 - 2.0 * s)
            channel = comp.channel or tex.channel
            wave = np.cos(2 * math.pi * (psi - np.floor(psi)))
            groups[channel][on] += gain * comp.amplitude * wave
    m_uv = np.clip(1 + groups[pb.CHANNEL_UV], 0, 1)  # R11
    m_ev = np.clip(1 + groups[pb.CHANNEL_EV], 1, 4)
    m_bi = np.clip(1 + groups[pb.CHANNEL_BIPOLAR], 0, 4)
    uv = np.where(texture >= 0, m_uv * np.minimum(m_bi, 1), 1.0)
    ev = np.where(texture >= 0, np.minimum(m_ev * np.maximum(m_bi, 1), 4), 1.0)
    return Reference(tau, uv, ev, texture.astype(np.int32))
