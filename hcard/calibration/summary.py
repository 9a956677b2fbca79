"""The answer of the calibration loop in one paragraph, for people (:func:`summarise`): the
held-out error before and after, the effects added, and what the verdict says is left in the
residual. :func:`hcard.calibration.loop.calibrate` puts it in
:attr:`~hcard.calibration.results.CalibrationResult.summary`, which the report and the command
print.
"""

from __future__ import annotations

from hcard.calibration.results import (
    AMBIGUOUS,
    EXPLAINED,
    NO_EFFECT,
    ModelFit,
    Structure,
    format_error,
)


def summarise(
    model: str,
    verdict: str,
    before: ModelFit,
    after: ModelFit,
    added: tuple[str, ...],
    structure: Structure,
    unit: str,
) -> str:
    """The result in one paragraph: the held-out RMSE ``before`` and ``after`` (in mN for a
    force ``unit`` of N), the effects ``added`` to ``model``, and what the ``verdict`` says is
    left in the residual (``structure``, small structure included)."""
    change = 1.0 - after.test_rmse / before.test_rmse
    text = (
        f"held-out RMSE {format_error(before.test_rmse, unit)} before, "
        f"{format_error(after.test_rmse, unit)} after ({-100 * change:+.1f} %). "
    )
    if added:
        text += f"Added to {model}: {', '.join(added)}. "
    small = structure.describe_small()
    left = (
        f"no structure above the practical threshold is left ({small})" if small
        else "no structure is left"
    )
    if verdict == NO_EFFECT:
        text += f"No effect needed: {model} explains the data; {left}."
    elif verdict == EXPLAINED:
        text += f"{left[0].upper()}{left[1:]} in the residual."
    elif verdict == AMBIGUOUS:
        text += (
            f"{left[0].upper()}{left[1:]} in the residual, but another model fits about as "
            "well."
        )
    else:
        text += f"Structured residual not explained by any known effect: {structure.describe()}."
        if small:
            text += f" Also {small}."
    return text
