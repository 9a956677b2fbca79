"""Every effect added by any path of the search passes the same selection test
(spec/calibration.md K27).

The recording is the independent generator's (tests/helpers/independent_recordings.py, numpy
from the thesis formulas): an ultrasonic plate with occlusion hidden (Fig. 1.11, tau_o 20 s)
and no speed effect. A move to the pair occlusion-drift + ultrasonic-speed, scored as the best by
``H``, is offered to the search's move step: ultrasonic-speed shows no structure against speed
in the base residual nor in occlusion-drift's (the model it would enter), and the second test
had the power to see it (``n_eff`` ~15,000), so the move is not made; the rule before K27
(:meth:`credited`, foreign structure only) would have made it.
"""

from __future__ import annotations

from hcard.calibration.judges import beyond_foreign_structure, claimed_regressors, usable_effects
from hcard.calibration.loop import EffectSearch, ResidualAnalyser
from hcard.calibration.model_pool import ModelPool
from hcard.calibration.results import LoopSettings
from hcard.calibration.screening import screening_mask
from hcard.plugins.registry import get_registry
from tests.helpers.independent_recordings import BASE_MODEL, Scenario, calibration_data


def test_a_move_never_brings_in_an_effect_its_own_test_refuses_k27() -> None:
    data = calibration_data(Scenario("uv", ("occlusion",)), seed=4)
    registry = get_registry()
    base = registry.get("predictor", BASE_MODEL["uv"])
    library = [e for e in registry.calibration_effects.values()
               if e.name in ("occlusion-drift", "ultrasonic-speed")]
    usable, _ = usable_effects(library, base, data.regressors)
    settings = LoopSettings(screen_samples=0)
    said: list[str] = []
    pool = ModelPool(data, base, tuple(base.calibrated), "lateral_force", screening_mask(
        data.train, 0), said.append)
    search = EffectSearch(data, pool, usable, claimed_regressors(base, usable), settings,
                          ResidualAnalyser(data, settings.bins), said.append, "N")
    load, speed = (next(e for e in usable if e.name == n)
                   for n in ("occlusion-drift", "ultrasonic-speed"))
    base_fit = search.current
    # the single-effect test of round 1: occlusion-drift passes (eta2 0.41),
    # ultrasonic-speed does not (0.0)
    eta2_load, ok_load = search.selection_test(load, base_fit)
    eta2_speed, ok_speed = search.selection_test(speed, base_fit)
    assert ok_load and eta2_load > 0.05
    assert not ok_speed and eta2_speed < settings.signature_eta2
    pair = pool.fitted_set([load, speed])
    assert pair is not None
    key = frozenset({"occlusion-drift", "ultrasonic-speed"})
    scores = {key: ([load, speed], pair, -1e9)}  # scored best by H
    # the old rule: credited() checks foreign structure only; with none, it lets speed in
    without = pool.fitted_set([load], exact=True)
    assert without is not None
    _, foreign = beyond_foreign_structure(
        speed, search.analyse(without), without.residuals[data.used],
        search.analyse.regressors, search.claimed, settings)
    assert foreign is None and search.credited(speed, [load, speed])
    # K27: refused on both residuals, the second test powered; the move is not made and the
    # decision is recorded
    assert search.refused_by_move_test(speed, [load, speed], base_fit)
    chosen = search._move(1, [], scores, frozenset(), 0.0, base_fit)
    assert chosen == []
    assert any("no structure against the signature of ultrasonic-speed (K27)" in line
               for line in said)
