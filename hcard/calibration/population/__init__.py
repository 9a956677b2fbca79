"""Population calibration: many recordings labelled by participant (or session, or device)
to one model with per-participant parameters and their population distribution
(spec/calibration.md section 7, rules K19-K25).

Two-stage mixed effects: :mod:`.grouping` sorts the recordings into groups by a sidecar
label, :mod:`.population_fit` fits each group with :func:`~hcard.calibration.fit.fit_predictor`
and chooses the population's effects, :mod:`.random_effects` pools each parameter's estimates
under a normal population, and :mod:`.report` writes the table and the forest plot.
"""
