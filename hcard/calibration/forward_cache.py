"""Outputs of a model's parts kept across the evaluations of one fit.

A least-squares fit (:func:`~hcard.calibration.fit.fit_predictor`) differentiates the model
numerically: each Jacobian evaluates it once per free parameter with that parameter stepped.
A step of one part's parameter (the finger's load index) leaves every other part's output as
it was at the unstepped point (the UV channel's relative friction, the inner model of the
lateral-force observation when only the force offset moves). Inside :func:`caching_forwards`
those outputs are kept by the part's exact parameter values (their bits) and its inputs
(the same array objects, scalars by value), so the same evaluation is not repeated: the
numbers are those of evaluating again, bit for bit.

Outside :func:`caching_forwards` (rendering, a real-time block reusing its buffers)
:func:`forward` evaluates every time. Inside it the inputs must not be changed in place
between calls (a fit's inputs never are).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Hashable, Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

import numpy as np

from hcard.physics import Predictor

PER_SLOT = 16
"""Outputs kept per part of a model: a Jacobian of ``k`` free parameters inserts at most
``k`` (one per step) besides the unstepped one, which each hit keeps fresh."""

_Entry = tuple[dict[str, Any], np.ndarray]
_STORE: ContextVar[dict[Hashable, OrderedDict[bytes, _Entry]] | None] = ContextVar(
    "hcard_forward_cache", default=None)


@contextmanager
def caching_forwards() -> Iterator[None]:
    """Keep the outputs :func:`forward` computes until the block ends (one store per block,
    per thread or task: a :class:`~contextvars.ContextVar`)."""
    token = _STORE.set({})
    try:
        yield
    finally:
        _STORE.reset(token)


def _same(kept: Any, given: Any) -> bool:
    """Whether ``given`` is the input ``kept``: the same array object, or a scalar (0-d) of
    the same dtype and bits."""
    if kept is given:
        return True
    if np.ndim(kept) or np.ndim(given):
        return False
    a, b = np.asarray(kept), np.asarray(given)
    return bool(a.dtype == b.dtype and a.tobytes() == b.tobytes())


def forward(slot: Hashable, model: Predictor, inputs: Mapping[str, Any]) -> np.ndarray:
    """``model.forward(**inputs)``, from the store when the block of :func:`caching_forwards`
    already evaluated it. ``slot`` names the part (with the class of the model it belongs
    to): ``model``'s kind and structure are fixed per slot; only its parameter values vary.
    A kept output is read-only."""
    store = _STORE.get()
    if store is None:
        return model.forward(**inputs)
    values = model._values
    key = np.fromiter(values.values(), dtype=np.float64, count=len(values)).tobytes()
    kept = store.setdefault(slot, OrderedDict())
    entry = kept.get(key)
    if entry is not None:
        given, out = entry
        if given.keys() == inputs.keys() and all(_same(given[k], inputs[k]) for k in given):
            kept.move_to_end(key)
            return out
    out = model.forward(**inputs)
    if isinstance(out, np.ndarray):
        out.setflags(write=False)
    kept[key] = (dict(inputs), out)
    kept.move_to_end(key)
    if len(kept) > PER_SLOT:
        kept.popitem(last=False)
    return out
