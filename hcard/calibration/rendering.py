"""The friction a device rendered, measured against the card's target (spec/calibration.md K17).

A device recording (spec/measurement-format.md, device columns of rule MF12) carries, per STATE
report, the lateral force ``F_l`` and the normal force ``F_n`` the device measured and the target
relative friction it was rendering (``target_uv * target_ev``, Eq. 4.1). The card's unit is the
finger's natural friction (spec/README.md section 1.5: relative friction 1 is the surface as it
is), so a patch of the surface rendered at relative friction ``r`` is measured as

    ``r_measured = mu / mu0``,    ``mu = mean(F_l / F_n)`` over the patch,

with ``mu0`` the finger's natural friction coefficient at the same time: a finger's friction
drifts (occlusion raises it over seconds of contact, Fig. 1.11; it depends on the load, Eq. 2.35,
and on the speed, Fig. 1.12), so ``mu0`` is interpolated linearly in time between the plain
patches (target 1) of the same contact, the nearest one where there is only one side, the
median of all plain patches where the contact has none. Nothing here uses a model of the
actuator: the error is the rendering error of the device as a force sensor sees it.

A *patch* is a run of reports with one target value inside one contact (the finger crossing one
taxtel of a card of constant textures), counted from :data:`SETTLE_S` after the target changed
or the finger touched down (the plate and the amplifier settle), with at least
:data:`MIN_PATCH_REPORTS` reports. Averaging over a patch removes the force sensor's noise, so
what is left is the device's systematic error:

- ``patch_rms``: RMS over the modulated patches of ``r_measured - target``: the figure a
  calibration must cut; its noise floor is the sensor's noise over ``sqrt(reports per patch)``;
- ``rms``, ``mean_abs``, ``bias``: over every report of the modulated patches (noise included).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcard.calibration.dataset import friction_force
from hcard.calibration.measurement import Measurement, MeasurementError

MIN_NORMAL_FORCE_N = 0.05
"""Reports with less normal force are left out, N (the relative noise of ``F_l / F_n`` grows as
``1 / F_n``)."""

SETTLE_S = 0.03
"""Time after a touch-down and after a target change before reports count, s: two 10-90 %
rise times of the coupled stimulator's plate (about 15 ms, section 4.3.2)."""

MIN_PATCH_REPORTS = 20
"""Counted reports a patch needs to enter ``patch_rms``."""

TARGET_STEP = 1e-4
"""A target that moves by more than this between two reports starts a new patch."""


@dataclass(frozen=True)
class RenderingError:
    """Measured against target relative friction (module docstring).

    Attributes:
        patch_rms: RMS over the modulated patches of the patch's error, relative friction.
        patches: modulated patches measured.
        rms: RMS error over the reports of the modulated patches, relative friction.
        mean_abs: mean absolute error over those reports.
        bias: mean error (measured - target) over those reports.
        reports: reports of the modulated patches.
        mu0: the finger's natural friction coefficient (median over the plain patches).
        noise: standard deviation of the measured relative friction within a patch (the
            sensor's noise in relative friction).
    """

    patch_rms: float
    patches: int
    rms: float
    mean_abs: float
    bias: float
    reports: int
    mu0: float
    noise: float

    def text(self) -> str:
        """One line for people."""
        return (f"rms {self.patch_rms:.4f} over {self.patches} texture patches (per report: rms "
                f"{self.rms:.4f}, bias {self.bias:+.4f}, noise {self.noise:.4f}; relative "
                f"friction, {self.reports} reports, natural mu0 {self.mu0:.3f})")

    def to_dict(self) -> dict[str, float | int]:
        """JSON-ready figures."""
        return {
            "patch_rms": self.patch_rms, "patches": self.patches, "rms": self.rms,
            "mean_abs": self.mean_abs, "bias": self.bias, "reports": self.reports,
            "mu0": self.mu0, "noise": self.noise,
        }


def _runs(values: np.ndarray) -> np.ndarray:
    """Run index of each sample: a new run starts where ``values`` moves by more than
    :data:`TARGET_STEP`."""
    change = np.zeros(values.shape[0], dtype=bool)
    if values.shape[0]:
        change[0] = True
        change[1:] = np.abs(np.diff(values)) > TARGET_STEP
    return np.cumsum(change) - 1


def _age(t: np.ndarray, run: np.ndarray) -> np.ndarray:
    """Time since the start of each sample's run, s."""
    first = np.zeros(t.shape[0], dtype=np.int64)
    starts = np.flatnonzero(np.diff(run, prepend=-1) != 0)
    first[starts] = starts
    first = np.maximum.accumulate(first)
    return t - t[first]


def _patches(m: Measurement, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per report, its patch number (-1: not counted) and its contact number."""
    fn = m.normal_force
    touching = m.in_contact & (fn >= MIN_NORMAL_FORCE_N)
    landed_or_lifted = np.diff(touching.astype(np.int8), prepend=0) != 0
    contact = np.cumsum(landed_or_lifted)
    contact_age = _age(m.t, contact)
    run = np.cumsum((np.diff(_runs(target), prepend=-1) != 0) | landed_or_lifted)
    counted = touching & (contact_age >= SETTLE_S) & (_age(m.t, run) >= SETTLE_S)
    patch = np.where(counted, run, -1)
    sizes = np.bincount(np.maximum(patch, 0), weights=counted.astype(float))
    patch = np.where(counted & (sizes[np.maximum(patch, 0)] >= MIN_PATCH_REPORTS), patch, -1)
    return patch, contact


def _members(patch: np.ndarray) -> list[np.ndarray]:
    """The report indices of each patch (patch numbers >= 0, ascending), each in report order;
    one sort, not one scan of the recording per patch (an hour's recording has thousands)."""
    counted = np.flatnonzero(patch >= 0)
    order = counted[np.argsort(patch[counted], kind="stable")]
    starts = np.flatnonzero(np.diff(patch[order], prepend=-1) != 0)
    return np.split(order, starts[1:]) if order.size else []


def _local_reference(times: np.ndarray, contacts: np.ndarray, mus: np.ndarray,
                     plain: np.ndarray, fallback: float) -> np.ndarray:
    """``mu0`` at each patch: interpolated in time between the plain patches of its contact,
    the nearest where there is one side only, ``fallback`` without any."""
    out = np.full(times.shape, fallback)
    for contact in np.unique(contacts):
        here = contacts == contact
        reference = here & plain
        if reference.any():
            order = np.argsort(times[reference])
            out[here] = np.interp(times[here], times[reference][order], mus[reference][order])
    return out


def rendering_error(m: Measurement) -> RenderingError:
    """The rendering error of a device recording (module docstring).

    Raises:
        MeasurementError: the recording has no ``target_uv``/``target_ev`` columns, no plain
            patch (target 1) to measure the finger's natural friction on, or no modulated patch
            to measure.
    """
    uv, ev = m.column("target_uv"), m.column("target_ev")
    if uv is None or ev is None:
        raise MeasurementError(
            "the recording has no target_uv and target_ev columns (rule MF12): it was not made "
            "through a device, so there is no target to compare with"
        )
    target = uv * ev
    fn = m.normal_force
    patch, contact = _patches(m, target)
    lateral = friction_force(m.lateral_force, m.speed, patch >= 0)
    mu = np.divide(lateral, fn, out=np.zeros_like(fn), where=fn > 0)
    members = _members(patch)
    times = np.array([m.t[k].mean() for k in members])
    contacts = np.array([contact[k[0]] for k in members])
    means = np.array([mu[k].mean() for k in members])
    targets = np.array([target[k].mean() for k in members])
    plain = np.abs(targets - 1.0) < TARGET_STEP
    if np.count_nonzero(plain) == 0:
        raise MeasurementError(
            "no plain patch (target 1 for at least "
            f"{MIN_PATCH_REPORTS} settled reports in contact) to measure the finger's natural "
            "friction on: play a card with plain patches between the textures"
        )
    if np.all(plain):
        raise MeasurementError("no modulated patch (target other than 1) to measure")
    fallback = float(np.median(means[plain]))
    if not fallback > 0:
        raise MeasurementError(f"the finger's natural friction coefficient is {fallback:g}")
    mu0 = _local_reference(times, contacts, means, plain, fallback)
    modulated = np.flatnonzero(~plain)
    patch_errors = means[modulated] / mu0[modulated] - targets[modulated]
    report_errors = np.concatenate(
        [mu[members[i]] / mu0[i] - target[members[i]] for i in modulated]
    )
    spreads = [float(np.var(mu[members[i]] / mu0[i])) for i in modulated]
    return RenderingError(
        patch_rms=float(np.sqrt(np.mean(patch_errors**2))),
        patches=int(modulated.size),
        rms=float(np.sqrt(np.mean(report_errors**2))),
        mean_abs=float(np.mean(np.abs(report_errors))),
        bias=float(np.mean(report_errors)),
        reports=int(report_errors.size),
        mu0=fallback,
        noise=float(np.sqrt(np.mean(spreads))),
    )
