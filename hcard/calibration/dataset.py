"""Recordings made ready for the calibration loop: model inputs, observed force, regressors, splits.

:func:`prepare` turns one or more :class:`~hcard.calibration.measurement.Measurement` objects
into a :class:`CalibrationData`: the arrays a predictor (with its effects) is fitted on, the
observed lateral force, every regressor the residual analysis looks at, and a held-out split by
stroke or by time block (spec/measurement-format.md section 4; never by random sample).

Several recordings are concatenated: the ``time`` input restarts at 0 in each (the filters of
time-dependent effects restart where time decreases, :mod:`hcard.calibration.time_series`),
strokes are numbered per recording, and the ambient pressure of each recording's sidecar becomes the
``pressure`` input of its samples (several recordings at different pressures make the
squeeze-film share identifiable, Fig. 2.12).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from hcard.calibration.contact import (
    check_threshold,
    contact_warning,
    default_contact_threshold,
    in_contact,
)
from hcard.calibration.measurement import Measurement, MeasurementError
from hcard.calibration.noise import NoiseModel, measure_noise
from hcard.calibration.splits import (
    CONTACT_THRESHOLD_N,
    SPLITS,
    split_by_stroke,
    stroke_ids,
)
from hcard.calibration.time_series import recent_change, time_since_change
from hcard.physics import Predictor
from hcard.quantities import ATMOSPHERE_PA, MN_PER_N

REST_S = 0.5
"""A pause out of contact (or a time gap) longer than this rests the finger, s: the stroke
count since rest (the ``stroke`` input) restarts at 0."""

HISTORY_WINDOW_S = 0.01
"""Window of the ``amplitude_history`` regressor (signed amplitude change), s."""



@dataclass(frozen=True)
class CalibrationData:
    """Samples of one or more recordings, ready for :func:`hcard.calibration.loop.calibrate`.

    Every sample is kept, in time order within each recording and recordings in the order
    given, so that effects with memory see the whole input history; only samples in contact
    (stroke id >= 0) are in the training or held-out split, and only they are fitted and
    analysed (:attr:`used`).

    Attributes:
        inputs: model inputs by name, SI units, each shape (n,): ``normal_force`` (N),
            ``time`` (s since the recording began), ``contact_time`` (s since the finger last
            touched down, 0 out of contact), ``occlusion_time`` (s in contact since the
            recording began, lifts excluded: the occlusion clock), ``stroke`` (strokes since
            the finger last rested), ``pressure`` (Pa), and when recorded ``amplitude`` (m,
            peak-to-peak), ``voltage`` (V), ``speed`` (m/s, magnitude), ``plate_frequency``
            (Hz: the plate's vibration frequency, from the ``frequency`` column or the
            sidecar; a model's ``frequency`` input when the model takes an ``amplitude``).
        observed: lateral (friction) force opposing the motion, N, shape (n,): the recorded
            force signed by the direction of the speed when there is a speed column, else
            its magnitude.
        regressors: arrays the residual analysis looks at (module
            :mod:`hcard.physics.effects` names, plus ``x``, ``y`` in m and ``recording``
            when there are several), shape (n,) each. Regressors that do not vary are left out.
        train: mask of the training samples, shape (n,).
        test: mask of the held-out samples, shape (n,).
        recording: index of each sample's recording, shape (n,).
        sources: a label per recording (its device and file, when known).
        sample_rate_hz: median sampling rate, Hz.
        split: how the held-out set was drawn (text).
        conditions: each recording's sidecar.
        time_ordered: whether the samples are a time series (False for steady-state points,
            e.g. a table of measurements): the loop then ignores structure in sample order.
        zeroing: per recording re-zeroed, ``(lifts, drift)``: the number of lifts at which the
            lateral-force zero was measured and the peak-to-peak of that zero, N.
        contact_threshold_n: per recording, the normal force at and above which a sample is in
            contact, N (:mod:`hcard.calibration.contact`).
        warnings: what a reader must know about the data (e.g. a stroke column that disagrees
            with the forces), one sentence each.
        noise: the lateral-force sensor's noise (AR(1)) measured on the samples out of contact
            after re-zeroing (:func:`~hcard.calibration.noise.measure_noise`), or None without
            lifts long enough to measure it.
        strokes: a stroke number per sample, unique over all recordings (-1 out of contact),
            shape (n,); empty when not known (each run of fitted samples is then one stroke,
            :meth:`stroke_labels`).
    """

    inputs: dict[str, np.ndarray]
    observed: np.ndarray
    regressors: dict[str, np.ndarray]
    train: np.ndarray
    test: np.ndarray
    recording: np.ndarray
    sources: tuple[str, ...]
    sample_rate_hz: float
    split: str
    conditions: tuple[dict, ...] = field(default_factory=tuple)
    time_ordered: bool = True
    zeroing: tuple[tuple[int, float], ...] = ()
    contact_threshold_n: tuple[float, ...] = ()
    warnings: tuple[str, ...] = ()
    strokes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    noise: NoiseModel | None = None

    def stroke_labels(self) -> np.ndarray:
        """A stroke number per sample (-1 where not fitted), unique over all recordings:
        :attr:`strokes` when known, else each run of consecutive fitted samples."""
        if self.strokes.shape == self.observed.shape:
            return np.where(self.used, self.strokes, -1)
        used = self.used.astype(np.int8)
        starts = np.diff(np.concatenate([[0], used])) == 1
        return np.where(self.used, np.cumsum(starts) - 1, -1)

    def __len__(self) -> int:
        return int(self.observed.shape[0])

    def inputs_for(self, model: Predictor) -> dict[str, np.ndarray]:
        """The inputs ``model`` declares, by its names: the plate frequency becomes the
        ``frequency`` input of a model that takes an ``amplitude`` (a UV model; an EV model's
        ``frequency`` is its voltage's, which a recording does not give)."""
        available = dict(self.inputs)
        names = {v.name for v in model.inputs}
        if "plate_frequency" in available and "amplitude" in names:
            available["frequency"] = available["plate_frequency"]
        return {name: values for name, values in available.items() if name in names}

    @property
    def used(self) -> np.ndarray:
        """Mask of the samples fitted or held out (in contact), shape (n,)."""
        return self.train | self.test

    def subset(self, mask: np.ndarray) -> dict[str, np.ndarray]:
        """The inputs restricted to ``mask`` (a boolean array of length n)."""
        return {name: values[mask] for name, values in self.inputs.items()}


def strokes_since_rest(t: np.ndarray, ids: np.ndarray, rest_s: float = REST_S,
                       moving: np.ndarray | None = None) -> np.ndarray:
    """Per sample, the number of strokes since the finger last rested (0, 1, 2, ...).

    ``ids`` are stroke ids (-1 out of contact, :func:`hcard.calibration.splits.stroke_ids`).
    A rest is a pause longer than ``rest_s`` (s) between the last sample of one stroke and the
    first of the next, or the start of the recording. Samples out of contact get -1.

    ``moving`` (per sample, the finger slides; default: every sample): only strokes that slide
    count. A stroke id without a moving sample (a finger held still at a touch-down, or a
    pause between two slides) is no pass over the skin (Figs. 2.25-2.26), so it takes the
    count of the sliding strokes before it and does not advance it: a touch-down hold followed
    by an out-and-back slide counts 0, 0, 1, not 0, 1, 2.
    """
    out = np.full(ids.shape, -1, dtype=np.int64)
    strokes = np.unique(ids[ids >= 0])
    slid = 0  # sliding strokes since the last rest
    last_end = -math.inf
    for stroke in strokes:
        where = np.flatnonzero(ids == stroke)
        start, end = float(t[where[0]]), float(t[where[-1]])
        if start - last_end > rest_s:
            slid = 0
        out[where] = slid
        if moving is None or bool(np.any(moving[where])):
            slid += 1
        last_end = end
    return out


NORMAL_FORCE_WINDOW_S = 0.01
"""The normal force a model sees is the moving median of the recorded one over this window, s,
within each contact (spec/calibration.md K16): a force sensor's noise is white while the
finger's load changes slowly or in steps, and a model fed the raw force carries the noise into
its prediction, where it correlates with the recorded force (errors in the variables) and shows
as residual structure against the normal force. A median keeps the steps of a load that
changes from stroke to stroke where a mean would smear them."""


CONTACT_GAP_PERIODS = 5.0
"""A sample interval longer than this many median sample periods is a gap in the recording,
not contact time, even where both samples around it are in contact (spec/calibration.md K30):
a recording that leaves out its lift samples would otherwise count every lift as contact."""


def accumulated_contact_time(t: np.ndarray, contact: np.ndarray,
                             gap_periods: float = CONTACT_GAP_PERIODS) -> np.ndarray:
    """Time spent in contact up to each sample, s: the sum of the sample intervals that end in
    contact (the dynamic occlusion time of Fig. 1.11b, which stops while the finger is lifted),
    each at most ``gap_periods`` median sample periods long; a longer interval is a gap (lift
    samples left out of the recording, K30) and adds one median period, as the first contact
    sample after a lifted one does. ``t`` in s, ascending;
    ``contact`` boolean, same shape."""
    t = np.asarray(t, dtype=np.float64)
    touching = np.asarray(contact, dtype=bool)
    steps = np.diff(t, prepend=t[:1])
    if t.size > 1:
        period = float(np.median(steps[1:]))
        steps = np.where(steps > gap_periods * period, period, steps)
    return np.cumsum(steps * touching)


def smoothed_within(values: np.ndarray, t: np.ndarray, runs: np.ndarray,
                    window_s: float) -> np.ndarray:
    """The moving median of ``values`` over a centred window of ``window_s`` (s) of samples,
    separately inside each run of ``runs`` (True samples; the others are returned as they
    are; the window is cut at a run's ends)."""
    out = np.asarray(values, dtype=np.float64).copy()
    if out.size < 3 or window_s <= 0:
        return out
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    half = round(window_s / step / 2) if step > 0 else 0
    if half < 1:
        return out
    from scipy.ndimage import median_filter  # here: scipy.ndimage costs ~0.25 s to import

    edges = np.flatnonzero(np.diff(np.concatenate([[0], runs.astype(np.int8), [0]])))
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        out[start:end] = median_filter(out[start:end], size=2 * half + 1, mode="nearest")
    return out


MIN_LIFT_SAMPLES = 3
"""Out-of-contact samples a lift needs for its zero to count."""

MIN_LIFTS_FOR_TREND = 3
"""Lifts needed before the zero's trend is continued past the first and last lift."""


def sensor_zero(
    t: np.ndarray, lateral: np.ndarray, contact: np.ndarray
) -> tuple[np.ndarray, int]:
    """The lateral-force sensor's zero over a recording, N, and the number of lifts used.

    While the finger is lifted the sensor reads its own zero (offset plus drift). The zero of
    each lift (a run of at least :data:`MIN_LIFT_SAMPLES` out-of-contact samples) is the median
    of its samples, placed at the run's mean time; between lifts it is interpolated linearly in
    time; before the first (after the last) lift it continues with the slope of a least-squares
    line through all lifts (weighted by their length) when there are at least
    :data:`MIN_LIFTS_FOR_TREND`, else it is held constant. A recording without a lift gets a
    zero of 0 (the fitted ``force_offset`` then takes a constant zero).
    """
    off = ~contact
    edges = np.flatnonzero(np.diff(np.concatenate([[0], off.astype(np.int8), [0]])))
    times: list[float] = []
    values: list[float] = []
    weights: list[float] = []
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        if end - start >= MIN_LIFT_SAMPLES:
            times.append(float(np.mean(t[start:end])))
            values.append(float(np.median(lateral[start:end])))
            weights.append(float(end - start))
    if not times:
        return np.zeros_like(lateral), 0
    zero = np.interp(t, times, values)
    if len(times) >= MIN_LIFTS_FOR_TREND:
        # Before the first and after the last lift: the trend of all lifts (least squares,
        # weighted by their length), from the end lift's zero.
        slope = float(np.polyfit(times, values, 1, w=np.sqrt(weights))[0])
        before, after = t < times[0], t > times[-1]
        zero[before] = values[0] + slope * (t[before] - times[0])
        zero[after] = values[-1] + slope * (t[after] - times[-1])
    return zero, len(times)


def friction_force(
    lateral: np.ndarray, speed: np.ndarray | None, contact: np.ndarray
) -> np.ndarray:
    """The friction force opposing the motion, N, from the recorded lateral force.

    Tribometers record the lateral force either signed by the direction of motion (with either
    sign convention) or as a magnitude (rule MF3). When the sign of the force follows the sign
    of the speed on at least 3/4 of the contact samples (or its opposite), the force is signed
    and is multiplied by the direction (so that a sensor offset stays an offset per direction);
    otherwise it is a magnitude, taken with the sign of most contact samples.
    """
    if speed is not None:
        direction = np.where(speed < 0, -1.0, 1.0)
        moving = contact & (speed != 0)
        if moving.any():
            agreement = float(np.mean(np.sign(lateral[moving]) * direction[moving]))
            if abs(agreement) >= 0.5:
                return lateral * direction * math.copysign(1.0, agreement)
    majority = float(np.mean(np.sign(lateral[contact]))) if contact.any() else 1.0
    return lateral if majority >= 0 else -lateral


def split_by_time_fraction(m: Measurement, test_fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices ``(train_idx, test_idx)``: the last ``test_fraction`` of the recording's
    duration is held out (one time block, rule MS4), the rest trains."""
    span = float(m.t[-1] - m.t[0])
    test = m.t >= m.t[0] + (1.0 - test_fraction) * span
    if span <= 0 or test.all() or not test.any():
        raise MeasurementError("a split by time needs a recording longer than one sample")
    return np.flatnonzero(~test), np.flatnonzero(test)


def _label(m: Measurement, index: int) -> str:
    device = m.conditions.get("device", "?")
    source = m.source
    return f"{source} ({device})" if source else f"recording {index} ({device})"


INPUT_NAMES = (
    "normal_force",
    "time",
    "contact_time",
    "occlusion_time",
    "stroke",
    "pressure",
    "amplitude",
    "voltage",
    "speed",
    "plate_frequency",
)
"""The columns of a recording that are model inputs (:attr:`CalibrationData.inputs`)."""

REGRESSOR_NAMES = (
    "normal_force",
    "speed",
    "direction",
    "amplitude",
    "voltage",
    "pressure",
    "plate_frequency",
    "time",
    "occlusion_time",
    "stroke",
    "amplitude_history",
    "voltage_history",
    "x",
    "y",
)
"""The columns of a recording the residual analysis looks at, when they vary
(:attr:`CalibrationData.regressors`; ``recording`` is added for several recordings)."""


def check_recordings(measurements: Sequence[Measurement], split: str,
                     test_fraction: float) -> None:
    """Refuse what :func:`prepare` cannot concatenate or split.

    Raises:
        MeasurementError: no recordings, an unknown ``split``, a ``test_fraction`` outside
            (0, 1), recordings with different actuation columns (amplitude, voltage), a column
            (speed, x, y, stroke) or a plate frequency in some recordings but not all (naming
            the recordings that lack it).
    """
    if not measurements:
        raise MeasurementError("no recordings to calibrate on")
    if split not in SPLITS:
        raise MeasurementError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    if not 0.0 < test_fraction < 1.0:
        raise MeasurementError(f"test_fraction must lie in (0, 1), got {test_fraction}")
    columns = {(m.amplitude is not None, m.voltage is not None) for m in measurements}
    if len(columns) > 1:
        raise MeasurementError(
            "recordings differ in their actuation columns (amplitude, voltage); calibrate "
            "recordings of one kind together"
        )
    for column in ("speed", "x", "y", "stroke"):
        have = [getattr(m, column) is not None for m in measurements]
        if any(have) and not all(have):
            lacking = ", ".join(
                _label(m, i) for i, m in enumerate(measurements) if getattr(m, column) is None
            )
            raise MeasurementError(
                f"column {column} is in some recordings but not in {lacking}; calibrate "
                "recordings with the same columns together"
            )
    plate = [
        m.plate_frequency is not None or bool(m.conditions.get("plate_frequency_hz"))
        for m in measurements
    ]
    if any(plate) and not all(plate):
        raise MeasurementError(
            "the plate frequency (column frequency or sidecar plate_frequency_hz) is given for "
            "some recordings but not all"
        )


def contact_time(t: np.ndarray, contact: np.ndarray) -> np.ndarray:
    """Per sample, the time since the current contact began, s (``t`` in s; the sample where
    ``contact`` turns True counts 0); 0 out of contact."""
    return np.where(contact, time_since_change(contact, t), 0.0)


def sliding(speed: np.ndarray | None, contact: np.ndarray) -> np.ndarray | bool:
    """The contact samples that slide (spec/measurement-format.md rule MS5).

    Where a recording has a speed column and some of its contact samples move, a contact
    sample whose speed is exactly 0 is a finger at rest on the surface (a touch-down before
    the first speed estimate, rule R4). Its lateral force is static friction, any value up to
    the sliding friction, which no sliding-friction model (Eqs. 1.7, 2.30, 4.1) describes, so
    it is neither fitted nor held out. True for every sample without a speed column or when
    no contact sample moves."""
    if speed is None:
        return True
    moving = speed != 0
    if not np.logical_or.reduce(moving & contact):
        return True
    return moving


def split_masks(m: Measurement, label: str, split: str, test_fraction: float, seed: int,
                threshold: float, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Masks ``(train, test)`` of the samples of ``m`` (``label`` names it in errors):
    ``split`` ``"stroke"`` holds out ``test_fraction`` of its strokes (drawn with ``seed``,
    strokes where the normal force reaches ``threshold``, N), ``"time"`` the last
    ``test_fraction`` of its duration; both only where ``keep`` (in contact)."""
    n = len(m)
    train = np.zeros(n, dtype=bool)
    test = np.zeros(n, dtype=bool)
    try:
        if split == "stroke":
            train_idx, test_idx = split_by_stroke(m, test_fraction, seed, threshold)
        else:
            train_idx, test_idx = split_by_time_fraction(m, test_fraction)
    except MeasurementError as exc:
        raise MeasurementError(f"{label}: {exc}") from None
    train[train_idx] = True
    test[test_idx] = True
    return train & keep, test & keep


def recording_columns(m: Measurement, index: int, ids: np.ndarray, contact: np.ndarray,
                      force: np.ndarray, rest_s: float) -> dict[str, np.ndarray | None]:
    """Every column of the recording ``m`` (the ``index``-th) the loop may use, SI units,
    None where ``m`` lacks it: the model inputs (:data:`INPUT_NAMES`), the regressors
    (:data:`REGRESSOR_NAMES`), the ``observed`` friction ``force`` (N) and the ``recording``
    index. ``ids``: stroke ids (-1 out of contact); ``contact``: per sample, a finger touches
    (:func:`~hcard.calibration.contact.in_contact`); ``rest_s``: pause that rests the finger,
    s."""
    n = len(m)
    speed = m.speed
    slides = sliding(speed, contact)
    moving = None if isinstance(slides, bool) else slides
    pressure = m.conditions.get("ambient_pressure_pa") or ATMOSPHERE_PA
    frequency = m.plate_frequency
    if frequency is None and m.conditions.get("plate_frequency_hz"):
        frequency = np.full(n, float(m.conditions["plate_frequency_hz"]))
    return {
        # Out of contact the recorded force is sensor noise around 0, which some models
        # refuse (Eq. 4.1 divides by Fn): those samples, never fitted, take the threshold.
        # In contact it is the recorded force smoothed over NORMAL_FORCE_WINDOW_S (K16).
        "normal_force": np.maximum(
            smoothed_within(m.normal_force, m.t, contact, NORMAL_FORCE_WINDOW_S),
            CONTACT_THRESHOLD_N,
        ),
        "time": m.t - m.t[0],
        "contact_time": contact_time(m.t, contact),
        "occlusion_time": accumulated_contact_time(m.t, contact),
        "stroke": strokes_since_rest(m.t, ids, rest_s, moving).astype(np.float64),
        "pressure": np.full(n, float(pressure)),
        "observed": force,
        "recording": np.full(n, float(index)),
        "amplitude": m.amplitude,
        "voltage": m.voltage,
        "speed": None if speed is None else np.abs(speed),
        # the sliding direction: a friction that differs between the two directions shows
        # against it, not only "in time"
        "direction": None if speed is None else np.sign(speed),
        "plate_frequency": frequency,
        "x": m.x,
        "y": m.y,
        "amplitude_history": None
        if m.amplitude is None
        else recent_change(m.amplitude, m.t, HISTORY_WINDOW_S),
        "voltage_history": None if m.voltage is None else time_since_change(m.voltage, m.t),
    }


@dataclass
class _Parts:
    """The per-recording pieces :func:`prepare` concatenates, in recording order."""

    columns: dict[str, list[np.ndarray]] = field(default_factory=dict)
    train: list[np.ndarray] = field(default_factory=list)
    test: list[np.ndarray] = field(default_factory=list)
    rates: list[float] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    zeroing: list[tuple[int, float]] = field(default_factory=list)
    thresholds: list[float] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    strokes: list[np.ndarray] = field(default_factory=list)
    lifted: list[np.ndarray] = field(default_factory=list)
    lifted_force: list[np.ndarray] = field(default_factory=list)
    times: list[np.ndarray] = field(default_factory=list)

    def add(self, m: Measurement, index: int, *, split: str, test_fraction: float, seed: int,
            rest_s: float, rezero: bool, contact_threshold_n: float | None) -> None:
        """Add the ``index``-th recording ``m`` (arguments of :func:`prepare`).

        Raises:
            MeasurementError: no sample in contact, or too few strokes (or samples) to split.
        """
        label = _label(m, index)
        threshold = (
            default_contact_threshold(m.normal_force)
            if contact_threshold_n is None
            else contact_threshold_n
        )
        self.thresholds.append(threshold)
        disagreement = contact_warning(m, threshold, label)
        if disagreement:
            self.warnings.append(disagreement)
        ids = stroke_ids(m, contact_threshold_n=threshold)
        keep = ids >= 0
        offset = max((int(part.max(initial=-1)) for part in self.strokes), default=-1) + 1
        self.strokes.append(np.where(keep, ids + offset, -1))
        if not keep.any():
            raise MeasurementError(
                f"{label}: no sample in contact (fn >= {threshold * MN_PER_N:.3g} mN)"
            )
        train, test = split_masks(m, label, split, test_fraction, seed + index, threshold,
                                  keep & sliding(m.speed, keep))
        self.train.append(train)
        self.test.append(test)

        lateral = m.lateral_force
        if rezero:
            zero, lifts = sensor_zero(m.t, lateral, keep)
            lateral = lateral - zero
            self.zeroing.append((lifts, float(np.ptp(zero))))
        force = friction_force(lateral, m.speed, keep)
        contact = in_contact(m, threshold)
        self.lifted.append(~contact)
        self.lifted_force.append(lateral)
        self.times.append(m.t)
        columns = recording_columns(m, index, ids, contact, force, rest_s)
        for name, values in columns.items():
            if values is not None:
                self.columns.setdefault(name, []).append(np.asarray(values, dtype=np.float64))
        if len(m) > 1:
            self.rates.append(1.0 / float(np.median(np.diff(m.t))))
        self.labels.append(label)


def prepare(
    measurements: Sequence[Measurement],
    *,
    split: str = "stroke",
    test_fraction: float = 0.25,
    seed: int = 0,
    rest_s: float = REST_S,
    rezero: bool = True,
    contact_threshold_n: float | None = None,
) -> CalibrationData:
    """Concatenate ``measurements`` into a :class:`CalibrationData` with a held-out split.

    Args:
        measurements: one or more recordings (every one needs ``amplitude`` or ``voltage``;
            all must record the same actuation columns).
        split: ``"stroke"``: hold out ``test_fraction`` of each recording's strokes (rule MS3,
            drawn with ``seed``); ``"time"``: hold out the last ``test_fraction`` of each
            recording's duration (a time block, rule MS4).
        test_fraction: share of strokes (or of time) held out, in (0, 1).
        seed: random seed of the stroke draw.
        rest_s: pause that rests the finger, s (see :func:`strokes_since_rest`).
        rezero: subtract the lateral-force sensor's zero, measured at every lift
            (:func:`sensor_zero`), so that its drift is not taken for friction.
        contact_threshold_n: normal force at and above which a sample is in contact, N
            (default: per recording,
            :func:`~hcard.calibration.contact.default_contact_threshold`, at least 10 mN). The
            forces decide contact even where a ``stroke`` column says otherwise; a column that
            disagrees gives a warning (:attr:`CalibrationData.warnings`).

    Raises:
        MeasurementError: no recordings, recordings with different actuation columns, a
            recording with too few strokes to split, or no sample in contact.
    """
    check_recordings(measurements, split, test_fraction)
    if contact_threshold_n is not None:
        contact_threshold_n = check_threshold(contact_threshold_n)
    parts = _Parts()
    for index, m in enumerate(measurements):
        parts.add(m, index, split=split, test_fraction=test_fraction, seed=seed, rest_s=rest_s,
                  rezero=rezero, contact_threshold_n=contact_threshold_n)

    joined = {
        name: np.concatenate(values)
        for name, values in parts.columns.items()
        if len(values) == len(measurements)
    }
    observed = joined.pop("observed")
    recording = joined.pop("recording").astype(np.int64)
    inputs = {name: joined[name] for name in INPUT_NAMES if name in joined}
    regressors = {
        name: joined[name]
        for name in REGRESSOR_NAMES
        if name in joined and np.ptp(joined[name]) > 0
    }
    if len(measurements) > 1:
        regressors["recording"] = recording.astype(np.float64)
    how = (
        f"by stroke: {test_fraction:.0%} of each recording's strokes held out (seed {seed})"
        if split == "stroke"
        else f"by time block: the last {test_fraction:.0%} of each recording's duration held out"
    )
    return CalibrationData(
        inputs=inputs,
        observed=observed,
        regressors=regressors,
        train=np.concatenate(parts.train),
        test=np.concatenate(parts.test),
        recording=recording,
        sources=tuple(parts.labels),
        sample_rate_hz=float(np.median(parts.rates)) if parts.rates else 1.0,
        split=how,
        conditions=tuple(dict(m.conditions) for m in measurements),
        zeroing=tuple(parts.zeroing),
        contact_threshold_n=tuple(parts.thresholds),
        warnings=tuple(parts.warnings),
        strokes=np.concatenate(parts.strokes),
        noise=measure_noise(np.concatenate(parts.lifted_force), np.concatenate(parts.lifted),
                            np.concatenate(parts.times)),
    )
