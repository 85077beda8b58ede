"""The messages both languages word: each a str.format template whose fields carry a format spec. Python formats
them with format(); harness/vibrofmu/fmus/native.py writes each into the native FMUs' rules.h as a printf format
(RULE_TEXT_<NAME>, printf_format: {name:.3g} -> %.3g, {name} -> %s), so the C passes only the values, in the
template's field order, and the words exist once. tests/fmus/test_native.py compares the logs of both."""
from __future__ import annotations

TEXTS = {
    # parameters.validate: x_start against the electrodes (native/scene_checks.c); fields: bound, gap
    "PULL_IN_START": "at or beyond pull-in x = 3R/2 = {bound:g} (gap 1-2x/(3R) = {gap:.3g})",
    "LOWER_START": "at or beyond the lower electrode x = -3R/2 = {bound:g} (gap 1+2x/(3R) = {gap:.3g})",
    # models.solver_tolerance's note (the native plant's model_initialise)
    "TOLERANCE_FACTOR": ("the solver runs at rtol = {solver_rtol:.3g} (rtol {rtol:.3g} x {factor:.3g}): the lightly "
                         "damped response remembers its errors over tau = {memory:.4g} (2/mu or the run's span), "
                         "rtol is kept per {reference:g} of it"),
    # parameters.clamp_tolerance's warning; requested: the value's exact text
    "RTOL_CLAMPED": ("parameter rtol = {requested} is below {floor:.3g} (100 machine epsilons: the error control "
                     "would see only rounding): using rtol = {floor:.3g}"),
    # fidelity auto (auto.choose; the native plant's model_initialise): the choice's log line (fmi2OK), the refusal
    # naming `tolerance`, and the parts of their lists of the candidates passed over
    "AUTO_CHOSE": ("fidelity auto chose {rung} (cost {cost:.3g} of exact at rtol 1e-8): its error estimate "
                   "{estimate:.3g} meets the tolerance {tolerance:g}{skipped}"),
    "AUTO_SKIPPED": "; skipped: {tried}",
    "AUTO_NONE": "no rung's error estimate meets it ({tried}); raise the tolerance",
    "AUTO_ESTIMATE": "{rung}: estimate {estimate:.3g}",
    "AUTO_REFUSED": "fidelity {level:g}: refused ({parameter})",
    # Python only (the native FMU has no rung with a set-up to weigh): a cheap rung not built
    "AUTO_SETUP": "{rung}: its set-up and run cost more than {fallback}'s run",
    # Python only: the averaged rung passed over unbuilt, its estimate's floor (auto.averaged_floor) above the tolerance
    "AUTO_FLOOR": "{rung}: its estimate is at least {floor:.3g} (its pre-check)",
    "AUTO_EXACT_RUNG": "fidelity {level:g} at rtol {rtol:g}",
    "AUTO_RUNG": "fidelity {level:g}",
}


def text(name: str, **values) -> str:
    """TEXTS[name] with `values`."""
    return TEXTS[name].format(**values)
