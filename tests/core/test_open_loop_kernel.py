"""Fidelities 3 and 4 evaluated in C (fmu_src/core/slowflow_eval.c, oafm_eval.c, openloop_plant.c through
vibromodel.compiled_open_loop), checked against the pure-Python plant they replace at run time.

Fidelity 3 performs the same IEEE operations in the same order as slowflow.SlowFlowSolution: equal bits.
Fidelity 4 builds each term's exp((-sigma + i nu) s) from a few base exponentials by recurrence (powers, products,
and steps in time) instead of one complex exp per term: equal to the Python sum within recurrence_error_bound,
which is derived term by term from the operations (see its docstring) -- not a fitted tolerance.
"""
import ctypes
import math

import numpy as np
import pytest

from vibrofmu.fmus.kernel import kernel_library
from vibrofmu.hosts.run import run_fmu
from vibromodel import compiled_open_loop as col
from vibromodel.analytic import OafmSettings
from vibromodel.oafm_bases import eq11_operator
from vibromodel.parameters import Scene
from vibromodel.plant import Plant, Settings, make_plant

NO_AC = Scene(beta=0.0, gamma=0.0)
LIGHT = Scene(mu=0.05, Delta=0.002, x_start=0.1, v_start=-0.05)  # a second scene: other rates, other fit


@pytest.fixture(scope="module")
def library():
    return kernel_library()


def compiled(scene, settings, library, stop_time=200.0):
    plant, why = col.CompiledOpenLoopPlant.make(Plant(scene, settings, 0.0, stop_time), library)
    assert plant is not None, why
    return plant


def outputs(o):
    return (o.x, o.v, o.a, o.F_contact, o.F_electrostatic, o.in_contact)


# ---------------------------------------------------------------- fidelity 3: the same bits

@pytest.mark.parametrize("scene, stop_time", [(Scene(), 200.0), (NO_AC, 200.0), (Scene(), None)],
                         ids=["paper example", "no AC (no psi)", "no stop time: the table grows past 200"])
def test_slow_flow_in_c_gives_the_python_plants_bits(library, scene, stop_time):
    settings = Settings(fidelity=3)
    python, c = Plant(scene, settings, 0.0, stop_time), compiled(scene, settings, library, stop_time)
    h = 0.1
    for i in range(3000 if stop_time is None else 2000):
        t = i * h  # the host's clock
        assert outputs(c.do_step(t, h, 0.0)) == outputs(python.do_step(t, h, 0.0)), t
    if stop_time is None:  # the C table was reloaded after Python extended it
        assert c.solution.t_end >= 300.0 and c._plant.slowflow.t_end == c.solution.t_end


# ---------------------------------------------------------------- fidelity 4: within the derived bound

def test_rates_are_written_in_the_scenes_own_frequencies():
    """The paper example's rates are integer combinations of q, omega, Omega and mu/2 (oafm_bases.harmonic_*):
    exactly those become the bases, and every combination reproduces its rate to rounding."""
    scene = Scene()
    solution = Plant(scene, Settings(fidelity=4), 0.0, 200.0).solution
    hints = col.oafm_hints(scene)
    program = col.OafmProgram(solution, *hints)
    assert program.reason is None
    q = eq11_operator(scene).q
    for terms in program.terms:
        assert sorted(terms["freq_bases"]) == sorted([q, scene.omega, scene.Omega])
        assert list(terms["decay_bases"]) == [0.5 * scene.mu]
        scale = np.abs(terms["freq_n"]) @ terms["freq_bases"] + terms["nu"]
        assert np.all(np.abs(terms["freq_n"] @ terms["freq_bases"] - terms["nu"]) <= col.MATCH_ULPS * col.EPS * scale)
        assert np.abs(terms["freq_n"]).max() <= 8  # order 3 of the harmonic family: small powers


def test_combinations_add_bases_only_where_needed_and_give_up_beyond_the_limit():
    # smallest first: 1 is a base, pi - 2 is not a combination of it, the rest are combinations of both
    bases, found = col.combinations([0.0, 1.0, 2.0, 3.0, math.pi, 1.0 + math.pi, math.pi - 2.0])
    assert bases == [1.0, math.pi - 2.0] and found[0.0] == (0,) * col.OE_BASES
    assert found[math.pi][:2] == (2, 1) and found[1.0 + math.pi][:2] == (3, 1) and found[3.0][:2] == (3, 0)
    independent = [math.sqrt(p) for p in (2, 3, 5, 7, 11, 13, 17)]  # no small integer relation among them
    assert col.combinations(independent) is None


def stepped_errors(plant, python, h, n, t0=0.0):
    """max over n doSteps of |C - Python| / bound for x, v, a."""
    worst = 0.0
    for i in range(n):
        t = t0 + i * h
        a, b = plant.do_step(t, h, 0.0), python.do_step(t, h, 0.0)
        bound = plant._program.error_bound(plant.t)
        worst = max(worst, max(abs(a.x - b.x), abs(a.v - b.v), abs(a.a - b.a)) / bound)
    return worst


@pytest.mark.parametrize("scene, oafm, h", [(Scene(), OafmSettings(), 0.1), (Scene(), OafmSettings(), 0.37),
                                            (LIGHT, OafmSettings(order=2), 1.0), (Scene(), OafmSettings(basis="paper"), 1.0)],
                         ids=["paper example, h 0.1", "paper example, h 0.37", "another scene, order 2, h 1",
                              "the paper's basis, h 1"])
def test_oafm_in_c_is_within_the_derived_bound_of_the_python_sum(library, scene, oafm, h):
    settings = Settings(fidelity=4, oafm=oafm)
    stop = 300.0  # past the fit's end (tau_end = 234.9 for the paper example): the extrapolation too
    plant, python = compiled(scene, settings, library, 200.0), Plant(scene, settings, 0.0, 200.0)
    assert stepped_errors(plant, python, h, int(stop / h)) <= 1.0
    # the bound is far below anything physical: the recurrence costs at most 1e-10 of max |x| here (the paper's basis,
    # with its larger cancelling coefficients, ~1e-11; the harmonic basis ~1e-12), while fidelity 4's model error on
    # the paper example is ~3e-9 absolute, ~1e-7 of max |x|
    grid = np.linspace(0.0, stop, 301)
    bounds = np.array([plant._program.error_bound(t) for t in grid])
    assert bounds.max() <= 1e-10 * np.abs(python.solution(grid)[0]).max()


def test_oafm_direct_evaluation_at_any_time(library):
    """vk_oafm_state (no cache) at times in any order, before the start, in both pieces and far beyond the fit."""
    scene, settings = Scene(), Settings(fidelity=4)
    plant = compiled(scene, settings, library)
    rng = np.random.default_rng(4)
    xva = (ctypes.c_double * 3)()
    for tau in np.concatenate([[-1.0, 0.0, plant.solution.pieces[1].start], rng.uniform(0.0, 600.0, 200)]):
        library.vk_open_loop_state(plant.address, tau, xva)
        expected = plant.solution.state(tau)
        bound = plant._program.error_bound(max(tau, 0.0), stepped=False)
        assert max(abs(a - b) for a, b in zip(xva, expected)) <= bound, tau


def test_snapshot_restores_the_step_cache_bit_for_bit(library):
    scene, settings = Scene(), Settings(fidelity=4)
    plant = compiled(scene, settings, library)
    for i in range(37):
        plant.do_step(i * 0.1, 0.1, 0.0)
    saved = plant.snapshot()
    first = [outputs(plant.do_step((37 + i) * 0.1, 0.1, 0.0)) for i in range(40)]
    plant.restore(saved)
    assert [outputs(plant.do_step((37 + i) * 0.1, 0.1, 0.0)) for i in range(40)] == first
    broken = {**saved, "oafm_cache": saved["oafm_cache"][:-2]}  # a truncated cache is refused
    with pytest.raises(ValueError):
        plant.restore(broken)
    tampered = dict(saved)  # a cache whose count is out of range is dropped: direct evaluation, still in bound
    cache = bytearray.fromhex(saved["oafm_cache"])
    cache[col.OeCache.count.offset] = 200
    tampered["oafm_cache"] = cache.hex()
    plant.restore(tampered)
    python = Plant(scene, settings, 0.0, 200.0)
    python.restore(saved["plant"])
    assert stepped_errors(plant, python, 0.1, 40, t0=3.7) <= 1.0


def test_make_plant_uses_c_where_it_can_and_says_why_not(library):
    library_pair = (library, "test library")
    for fidelity in (3, 4):
        plant = make_plant(Scene(), Settings(fidelity=fidelity), 0.0, 200.0, library=library_pair)
        assert isinstance(plant, col.CompiledOpenLoopPlant) and any("C evaluator" in note for note in plant.notes)
        python = make_plant(Scene(), Settings(fidelity=fidelity, kernel=1), 0.0, 200.0, library=library_pair)
        assert isinstance(python, Plant)
        missing = make_plant(Scene(), Settings(fidelity=fidelity), 0.0, 200.0, library=(None, "none here"))
        assert isinstance(missing, Plant) and any("none here" in note for note in missing.notes)


def test_refused_steps_raise_the_python_plants_errors(library):
    from vibromodel.parameters import ParameterError

    plant = compiled(Scene(), Settings(fidelity=4), library)
    for t, h, U, name in ((0.0, -0.1, 0.0, "communicationStepSize"), (0.0, 0.1, 1.0, "U"),
                          (5.0, 0.1, 0.0, "currentCommunicationPoint")):
        with pytest.raises(ParameterError) as error:
            plant.do_step(t, h, U)
        assert error.value.name == name
    assert plant.t == 0.0  # nothing moved


# ---------------------------------------------------------------- in the FMU: the C fast path

@pytest.mark.parametrize("fidelity", [3, 4])
def test_fmu_fast_path_at_fidelities_3_and_4_matches_the_python_fmu(plant_fmu, library, fidelity):
    compiled_run, python_run = (run_fmu(plant_fmu, {"fidelity": fidelity, "kernel": kernel}, 100.0, 0.1)
                                for kernel in (0, 1))
    assert compiled_run.completed and python_run.completed
    # the same FMPy loop computes the time grid for both kernels
    assert np.array_equal(compiled_run.time, python_run.time)
    if fidelity == 3:  # each kernel's FMU evaluates its own table (kernel 0 tabulates in C, core/slowflow_table.c;
        # 1 with SciPy): the in-process plant's table of the same kernel, stepped alike, gives the same bits (the same
        # operations in the same order, module docstring); the two tables' difference: tests/model/test_slowflow_kernel.py
        for kernel, run in ((0, compiled_run), (1, python_run)):
            plant = Plant(Scene(), Settings(fidelity=3, kernel=kernel), 0.0, 100.0)
            expected = [outputs(plant.outputs())]
            for i in range(len(run.time) - 1):  # run_fmu's loop: doStep(i h, h)
                expected.append(outputs(plant.do_step(i * 0.1, 0.1, 0.0)))
            for i, name in enumerate(("x", "v", "a")):
                assert np.array_equal(run.outputs[name], [row[i] for row in expected]), (kernel, name)
    else:  # the same fit (same cache), evaluated by recurrence: within the derived bound at every output
        program = compiled(Scene(), Settings(fidelity=4), library, 100.0)._program
        bound = np.array([program.error_bound(t) for t in compiled_run.time])
        for name in ("x", "v", "a"):
            assert np.all(np.abs(compiled_run.outputs[name] - python_run.outputs[name]) <= bound), name


@pytest.mark.parametrize("fidelity", [3, 4])
def test_fmu_steps_fidelities_3_and_4_without_python_and_restores_state(start_plant, fidelity):
    instance = start_plant(stop_time=40.0, fidelity=fidelity)
    try:
        fmu = instance.fmu
        refs = instance.value_references(["x", "v", "a", "F_contact", "F_electrostatic"])
        rows, saved = [], None
        for i in range(400):
            if i == 150:
                saved = fmu.getFMUstate()
            fmu.doStep(i * 0.1, 0.1)
            rows.append(fmu.getReal(refs))
        assert instance.fast_path_steps() == 400  # every doStep in C
        fmu.setFMUstate(saved)
        for i in range(150, 400):
            fmu.doStep(i * 0.1, 0.1)
            assert fmu.getReal(refs) == rows[i]
        assert instance.fast_path_steps() == 650
        fmu.freeFMUstate(saved)
    finally:
        instance.close()


# ---------------------------------------------------------------- bounded resources for long stop times (issue 15)

def test_slow_flow_tabulates_in_windows_and_keeps_its_memory_bounded(library):
    """Stop time 1e6: set-up tabulates slowflow.WINDOW only; the table grows CHUNK at a time as the run advances
    and drops the cells behind it, so cells and FMU state stay bounded; C and Python still agree bit for bit
    across the extensions."""
    from vibromodel import slowflow, snapshot

    scene, settings = Scene(), Settings(fidelity=3)
    python, c = Plant(scene, settings, 0.0, 1e6), compiled(scene, settings, library, 1e6)
    assert python.solution.t_end == slowflow.WINDOW
    window_cells = len(python.solution.cells)
    sizes = []
    for i in range(2500):
        assert outputs(c.do_step(float(i), 1.0, 0.0)) == outputs(python.do_step(float(i), 1.0, 0.0)), i
        if i in (100, 2499):
            sizes.append(len(snapshot.to_bytes({"model": c.snapshot()})))
    solution = python.solution
    assert solution.t_end >= 2500.0 and solution.first > 0  # extended, and the front dropped
    assert len(solution.cells) <= window_cells and len(c.solution.cells) <= window_cells
    assert sizes[1] <= sizes[0]  # the state does not grow with the run
    for state in (solution.state, c.state_at):  # Python, and C falling back to it
        with pytest.raises(ValueError, match="no longer holds"):
            state(10.0)
    assert c.state_at(3000.5) == python.solution.state(3000.5)  # beyond the table: extended, then the same bits


def test_fidelity_4_refuses_fits_beyond_its_limit_up_front():
    from vibromodel.analytic import MAX_FIT_SPAN
    from vibromodel.parameters import ParameterError

    cases = [(Scene(), OafmSettings(), 1e6, "stopTime"), (Scene(), OafmSettings(tau_end=1e308), 200.0, "oafm_tau_end"),
             (Scene(omega=5e-324), OafmSettings(), 200.0, "omega"), (Scene(Omega=5e-324), OafmSettings(), 200.0, "Omega")]
    for scene, oafm, stop, name in cases:
        with pytest.raises(ParameterError) as error:
            Plant(scene, Settings(fidelity=4, oafm=oafm), 0.0, stop)
        assert error.value.name == name
    with pytest.raises(ParameterError, match=f"at most tau = {MAX_FIT_SPAN:g}"):
        Plant(Scene(), Settings(fidelity=4), 0.0, 1e6)


def test_fmu_refuses_fidelity_4_with_stop_time_1e6_at_initialisation(plant_fmu):
    run = run_fmu(plant_fmu, {"fidelity": 4}, 1e6, 1e5)
    assert not run.completed and run.status == 3 and len(run.time) == 0  # refused at exitInitializationMode
    assert "stopTime" in run.message and "2000" in run.message
