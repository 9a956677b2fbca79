"""Physical effects the simulated hardware can hide: ``hcard device serve --effect NAME``.

A device served with an effect behaves differently from its own profile (the firmware's model,
:mod:`hcard_device.sim.models`) and says nothing about it: no report, no sidecar key names the
effect. It is how a test hides an effect in the hardware that a calibration must find from
recordings alone. Each effect runs the device's own physics code (here, with the physics
predictors of :mod:`hcard_builtins.physics`), never the calibration plugin's transform of the
same name. Effects take their parameters as ``NAME.PARAM=VALUE`` (units accepted:
``air-layer.air_gap=8um``); :data:`HIDDEN_EFFECTS` lists their parameters (unit, default = the
hidden truth when none is given, bounds, source), their neutral values (the un-hidden device
exactly) and which device can have each (``evita``: UV only; ``coupled``: UV and EV).

Effects of the calibration library (spec/calibration.md):

- ``load-index``: the finger's friction ``F = k Fn^n`` (Eqs. 1.7, 2.35) with ``n =
  load_index`` (default 0.75) instead of the device finger's 0.91. The calibration's finger
  model already fits ``finger.load_index``: the expected answer is that base parameter, not an
  added effect.
- ``occlusion-drift``: the dry friction times ``1 + g (1 - exp(-t / tau))`` (Fig. 1.11), ``t``
  the time in contact since the finger arrived, lifts excluded (Fig. 1.11b; it pauses while the
  finger is lifted and does not restart at a touch-down), on top of the device finger's own
  occlusion since touch-down. ``gain`` g (0.5), ``time_constant`` tau (30 s).
- ``actuator-bandwidth``: the vibration under the finger follows the amplitude the sensing
  piezos report through a first-order lag ``tau_a`` (the plate's mechanical response, section
  4.3.2: ~1.5 ms). The PI loop holds the sensed amplitude and the recording carries it, so the
  recorded amplitude leads what the finger feels. ``time_constant`` (1.5 ms; 0: none).
- ``charge-leakage``: the finger's stratum corneum leaks its bound charge with another time
  constant than the profile's (Eqs. 3.19-3.23): the carrier reaches the skin with the gain
  ``|H(f_c)|`` of Eq. 3.22 at the finger's ``tau_d(f_c)`` (Fig. 3.13: ``tau_d`` falls as
  ``f^-0.7``) instead of the profile's. The 440 Hz carrier is far faster than any envelope
  change, so on the envelope the leak is that gain (a touch-down's transient is under 0.5 % of
  the force): from envelope recordings it is not told from the EV area (the calibration says
  so). ``time_constant`` tau_d at 10 Hz (3 ms; the profile's 7.7 ms: none).
- ``ultrasonic-speed``: the ultrasonic reduction ``1 - mu'`` times ``(U / U_ref)^a``, capped
  at 1 (Fig. 2.21e: it falls with sliding speed). ``speed_exponent`` a (-0.5),
  ``reference_speed`` U_ref (25 mm/s).
- ``air-layer``: air trapped between the fingerprint ridges and the insulator, a third
  dielectric in series (Eq. 3.17, Fig. 3.7): the EV force is
  :class:`~hcard_builtins.physics.electrovibration.AirLayer` with the contact layers of the
  device's Kaczmarek model and a gap the load flattens, ``d_a = d_a1 (1 N / F_n)``, at the
  carrier-averaged voltage ``g V / sqrt 2`` (``g`` the leakage gain at the carrier).
  ``air_gap`` d_a1 (10 um: the force falls to about half at 0.5 N).
- ``skin-recovery``: the ridges do not spring back fully between passes (Figs. 2.25-2.26):
  the finger's friction times ``1 - D exp(-k / k_r)``, ``k`` the strokes since the finger last
  rested (:mod:`.finger_clock`: a reversal along x in contact or a touch-down starts a stroke;
  a lift of 0.5 s rests the finger). ``depth`` D (0.2), ``strokes`` k_r (2).
- ``squeeze-film-share``: the ultrasonic reduction times ``gamma = 1 - s (1 - p / p0)``
  (Eq. 2.10), ``p`` the device's ambient pressure (``DeviceConfig.ambient_pressure_pa``,
  ``hcard device serve --ambient-pressure``, ``sim://...?ambient_pressure=...``), ``p0`` one
  atmosphere. ``share`` s (0.5): invisible at one atmosphere.
- ``finger-geometry``: the EV force of the curved ridged pad of Table 3.2 flattening under
  load (Eq. 3.18, :mod:`.pad`) instead of the flat-plate law: the device's force times
  ``C(h_1 (Fn / 1 N)^m) / C(h_1)`` (equal to it at 1 N). ``area_index`` m (2/3, Hertz).

Effects no library effect explains:

- ``plate-load-damping``: the finger damps the mode under it (section 4.4): it feels
  ``A_sensed / (1 + Fn / F_d)`` while the sensing piezos, away from the finger, report
  ``A_sensed``. ``damping_force`` F_d (2 N; 1e6 N: none).
- ``force-sensor-resonance``: the lateral force sensor (a floating table on a force sensor,
  Fig. 2.5a) is a second-order system of unit static gain, natural frequency ``f0`` and damping
  ratio ``zeta``: the recorded lateral force is the true one through it (its noise added
  after). ``natural_frequency`` f0 (150 Hz; 1e5 Hz: an ideal sensor), ``damping_ratio`` zeta
  (0.1).

Stateful effects (occlusion time, strokes, the leakage high pass, the lag, the sensor) carry
their state from one simulation step to the next: the numbers do not depend on how the frames
are cut into steps. A new finger (:meth:`HiddenPhysics.new_finger`) restarts the finger's
history; the hardware's filters run on.
"""

from hcard_device.sim.hidden.catalogue import (
    HIDDEN_EFFECTS,
    HiddenEffect,
    HiddenEffectError,
    parse_assignments,
    resolve,
)
from hcard_device.sim.hidden.physics import HiddenPhysics

__all__ = ["HIDDEN_EFFECTS", "HiddenEffect", "HiddenEffectError", "HiddenPhysics",
           "parse_assignments", "resolve"]
