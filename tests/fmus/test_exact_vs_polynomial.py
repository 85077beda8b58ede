"""Exact Eq. 3 vs polynomial Eq. 7 (corrected and printed coefficients) on the paper example."""
import numpy as np
import pytest


@pytest.fixture(scope="module")
def runs(run_plant):
    return {f: run_plant(fidelity=f, rtol=1e-12) for f in (0, 1, 2)}


def difference(a, b):
    assert a.completed and b.completed
    return float(np.max(np.abs(a.outputs["x"] - b.outputs["x"])))


def test_exact_and_corrected_polynomial_agree_to_1e11(runs):
    # docs/model.md, The paper's example reproduced: 1.07e-12 (series truncation at |x| <= 0.04); each run carries ~3e-13 integration error
    assert difference(runs[0], runs[1]) <= 1e-11


def test_printed_coefficients_differ_by_about_2e8(runs):
    # docs/model.md, The paper's example reproduced: 2.27e-8, caused by the printed a3, a4, a5
    d = difference(runs[0], runs[2])
    assert 1.5e-8 <= d <= 3.0e-8, d


def test_polynomial_outputs_are_consistent(runs):
    run = runs[1]
    t, out = run.time, run.outputs
    # acceleration output = x'' of Eq. 7 vs a central difference of v: error h^2/6 max|v'''|
    # with h = 0.1 and |v'''| <= A omega^4 ~ 0.04 gives 7e-5
    dv = (out["v"][2:] - out["v"][:-2]) / (t[2:] - t[:-2])
    assert np.max(np.abs(dv - out["a"][1:-1])) <= 1e-4
    # F_contact is the series G1(x) ~ 1 + x
    assert np.max(np.abs(out["F_contact"] - (1 + out["x"]))) <= 0.04**2


# -- the registry is the one list of levels: what the rest derives from it is current -------------------------
def test_the_parameter_rule_is_the_registrys():
    """parameters.RULES cannot import the registry (its factories validate scenes with those rules: a cycle), so
    its `fidelity` rule and the open-loop levels' rules are written there and must equal what the registry says."""
    from vibromodel import fidelities, parameters

    rules = [rule for rule in parameters.RULES if rule.name == "fidelity"]
    assert rules == [fidelities.rule()]
    assert (rules[0].low, rules[0].high) == (min(fidelities.REGISTRY), max(fidelities.REGISTRY))
    whens = {rule.when[1] for rule in parameters.RULES if rule.when is not None and rule.when[0] == "fidelity"}
    assert whens == {fidelities.open_loop_rule_levels()}


def test_the_c_header_is_generated_from_the_registry():
    """core/fidelity.h is committed; regenerate it with `python3 -m vibrofmu.fmus.kernel`."""
    from vibrofmu.fmus import kernel
    from vibromodel.fidelities import c_header

    assert kernel.FIDELITY_HEADER.read_text() == c_header()


def test_the_entries_are_consistent():
    from vibromodel.fidelities import REGISTRY, Evaluator, native_refusal

    assert list(REGISTRY) == list(range(len(REGISTRY)))  # the C indexes VK_FIDELITIES by level
    for level, e in REGISTRY.items():
        assert e.level == level and e.description.split(" ", 1)[0] == str(int(level))
        assert e.integrated == (e.open_loop is None)
        assert (e.evaluator != Evaluator.NONE) <= (e.open_loop is not None)
        assert e.c_model is not None or native_refusal(level) is not None  # the native FMUs have no model for it
    ladder = [e for e in REGISTRY.values() if e.ladder]
    assert ladder and ladder[0].level == 0 and ladder[0].ladder_limit is None  # the base: the default fidelity
