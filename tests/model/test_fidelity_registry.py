"""The fidelity registry (vibromodel/fidelities.py) is the one list of levels: what the rest derives from it is
current."""


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
