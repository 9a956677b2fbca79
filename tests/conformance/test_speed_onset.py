"""A-sel's speed onsets (spec/conformance.md 3.1): before a contact's second touch sample a
renderer has no finger speed and holds the touch-down; at that sample the golden's position
and texture phase jump. A device shows the jump when the sample reaches it, one transport
delay later (judged by D3), so the frames around the onset are not compared by A1-A4."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hcard.track import make_track
from hcard_conformance import metrics
from hcard_conformance import renderer_level as rl
from hcard_conformance.context import Context
from tests.helpers.late_transport import LATE_S, LateSecondSampleDriver


def test_speed_onsets_are_the_second_sample_of_every_contact():
    # two contacts (samples 0-3 and 6-8), a lone touch (10) and one that starts at sample 12
    contact = np.array([1, 1, 1, 1, 0, 0, 1, 1, 1, 0, 1, 0, 1, 1], dtype=bool)
    t = np.arange(contact.size) * 0.02
    track = make_track(t, np.linspace(0, 10, t.size), np.zeros(t.size), 0.5, contact)
    np.testing.assert_allclose(metrics.speed_onsets(track), [0.02, 0.14, 0.26])


@pytest.mark.parametrize("name", ["single-grating@liftoff", "single-grating@moderate-stroke"])
def test_a_late_second_sample_is_judged_by_d3_not_by_a1(name):
    """Through a transport that delays the second sample of each contact by 9 ms (inside
    the D3 bound), the reference device passes A1 with room to spare."""
    ctx = Context("sim://late", LateSecondSampleDriver, options={"renders": [name]})
    entry = next(e for e in ctx.manifest.renders if e.name == name)
    data = rl.case(ctx, entry)
    tol = rl.tolerances(ctx, entry)
    assert tol.latency_s >= LATE_S
    guarded = metrics.relative_error(data["impl"], data["golden"], tol)
    assert guarded.value < 0.03, guarded.detail
    if name.endswith("liftoff"):
        # judged without the speed-onset guard, the same frames fail A1: the guard is what
        # tells a late sample from a wrong render (on the moderate stroke the 100 Hz grating
        # lets the lag search absorb it a period later, so only the liftoff shows it)
        unguarded = metrics.relative_error(data["impl"], replace(data["golden"], events=None),
                                           tol)
        assert unguarded.value > tol.friction_rel_jnd, unguarded.detail
