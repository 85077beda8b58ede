"""vibrofmu.api (the plant at kernel speed from Python) against CompiledPlant stepped as a host steps it (the plant
FMU's own path, whose bits the FMU tests check): the same bits, the same refusals and messages, the same stops."""
import math

import numpy as np
import pytest

from vibrofmu import api
from vibrofmu.fmus import kernel
from vibromodel.compiled import CompiledPlant
from vibromodel.integrate import TerminalEvent
from vibromodel.parameters import RULES, ParameterError, Scene, scene_names
from vibromodel.plant import Settings, Solver
from vibromodel.settings import checked_settings


@pytest.fixture(scope="module")
def library():
    return kernel.kernel_library()


def host_run(library, scene, settings, stop_time, interval, start_time=0.0):
    """CompiledPlant stepped from start_time + k interval (as a host computes the points): the outputs at each
    point, and the exception that stopped it (None)."""
    plant = CompiledPlant(scene, settings, library, start_time, stop_time)
    rows, error = [(start_time, plant.outputs())], None
    for k in range(round((stop_time - start_time) / interval)):
        t = start_time + k * interval
        try:
            rows.append((t + interval, plant.do_step(t, interval, 0.0)))
        except (TerminalEvent, ArithmeticError, ValueError) as stopped:
            error = stopped
            break
    columns = {"time": np.array([t for t, _ in rows])}
    for name in api.OUTPUTS[1:]:
        columns[name] = np.array([getattr(out, name) for _, out in rows])
    return columns, error


def assert_same_run(run, expected, error):
    for name in api.OUTPUTS:
        got = getattr(run, name)
        assert np.array_equal(got, expected[name]), (name, got[:5], expected[name][:5])
    assert type(run.error) is type(error) and str(run.error) == str(error)
    assert run.stopped == ("" if error is None else f"{type(error).__name__}: {error}")


# scenes that exercise every path of the plant: the paper's, contact loss (tests/fmus/test_contact_loss.py's),
# light damping (the tolerance factor's note), no forcing (no drive ceiling), a larger DC load
SCENES = [Scene(), Scene(x_start=-1.3, v_start=-0.8, R=2.0), Scene(mu=0.005), Scene(Delta=0.0, beta=0.0, gamma=0.0),
          Scene(alpha=0.05, x_start=-0.3, v_start=0.2)]


@pytest.mark.parametrize("settings", [Settings(), Settings(rtol=1e-5), Settings(fidelity=1),
                                      Settings(solver=Solver.RK4, max_step=0.05)], ids=str)
def test_simulate_gives_the_host_run_bits(library, settings):
    for scene in SCENES:
        expected, error = host_run(library, scene, settings, 30.0, 0.1)
        assert_same_run(api.simulate(scene, 30.0, 0.1, settings), expected, error)


def test_contact_loss_scene_loses_contact(library):
    """SCENES[1] is the contact-loss scene of the bits test: it must open the contact, or that test misses it."""
    run = api.simulate(SCENES[1], 30.0, 0.1)
    assert not run.in_contact.all() and run.in_contact.any()


def test_many_scenes_are_each_the_single_run(library):
    """simulate_many over more scenes than one chunk, given as columns and as Scene objects, with a pull-in in the
    middle: every scene's rows are its own run, the stopped one's NaN after its stop."""
    rng = np.random.default_rng(35)
    m = api.CHUNK + 7
    columns = {"omega": rng.uniform(0.8, 1.2, m), "Delta": rng.uniform(0.0, 0.5, m), "mu": rng.uniform(0.005, 0.2, m)}
    columns["alpha"] = np.where(np.arange(m) == 40, 0.5, 0.001)
    columns["x_start"] = np.where(np.arange(m) == 40, 1.2, 0.04)  # scene 40 pulls in at once
    batch = api.simulate_many(columns, 5.0, 0.25)
    scenes = [Scene(**{name: float(values[i]) for name, values in columns.items()}) for i in range(m)]
    assert np.array_equal(api.simulate_many(scenes, 5.0, 0.25).x, batch.x, equal_nan=True)
    assert len(batch) == m and batch.x.shape == (m, 21)
    assert isinstance(batch.errors[40], TerminalEvent) and batch.n_points[40] < 21
    assert np.isnan(batch.x[40, batch.n_points[40]:]).all()
    assert [i for i in range(m) if batch.stopped[i]] == [40]
    for i in (0, 39, 40, 41, api.CHUNK, m - 1):
        expected, error = host_run(library, scenes[i], Settings(), 5.0, 0.25)
        assert_same_run(batch.run(i), expected, error)
        assert batch.notes[i] == CompiledPlant(scenes[i], Settings(), library, 0.0, 5.0).notes


@pytest.mark.parametrize("fidelity", [0, 1, 2])
def test_the_kernel_structures_are_compiled_plants(library, fidelity):
    """The model fields simulate_many fills for all scenes at once (the exact model) or per scene (Eq. 7) are the
    ones the level's model object gives CompiledPlant (models.*.compiled_fields), byte for byte."""
    import ctypes

    from vibromodel.core_layouts import VkModel

    scenes = SCENES + [Scene(Delta=0.0, beta=0.01, gamma=0.0, alpha=0.0), Scene(beta=0.0, gamma=0.003)]
    columns = api.scene_columns(scenes)
    plants = np.zeros(len(scenes), dtype=api.PLANT_DTYPE)
    api.fill_plants(plants, columns, Settings(fidelity=fidelity), 0.0, 10.0)
    for i, scene in enumerate(scenes):
        plant = CompiledPlant(scene, Settings(fidelity=fidelity), library, 0.0, 10.0)
        expected = ctypes.string_at(plant.address, ctypes.sizeof(VkModel))
        assert plants[i:i + 1].tobytes()[:ctypes.sizeof(VkModel)] == expected, scene


def test_notes_and_warnings_are_compiled_plants(library):
    """The tolerance factor's note (light damping over a long span) and RK4's drive warning, per scene."""
    scenes = [Scene(mu=0.001), Scene(), Scene(Omega=40.0)]
    said = []
    for settings in (Settings(), Settings(solver=Solver.RK4, max_step=0.05), Settings(rtol=1e-15)):
        batch = api.simulate_many(scenes, 400.0, 100.0, settings)
        for i, scene in enumerate(scenes):
            plant = CompiledPlant(scene, settings, library, 0.0, 400.0)
            assert batch.notes[i] == plant.notes and batch.warnings[i] == plant.warnings
        said.append(([bool(n) for n in batch.notes], [bool(w) for w in batch.warnings]))
    # what the comparison covered: the note for mu = 0.001 only (not with RK4), RK4's warning at Omega = 40, the
    # clamp's warning for every scene
    assert said == [([True, False, False], [False] * 3), ([False] * 3, [False, False, True]),
                    ([True, False, False], [True] * 3)]


def outside(rule):
    """A value just outside the rule's range (below its low end, or above its high end when that is open)."""
    return rule.low - max(1.0, abs(rule.low)) if math.isfinite(rule.low) else math.nan


@pytest.mark.parametrize("rule", [r for r in RULES if r.name in scene_names() and r.when is None], ids=lambda r: r.name)
def test_a_bad_scene_is_refused_as_compiled_plant_refuses_it(library, rule):
    """Each scene rule: the error (type and message) CompiledPlant raises, the scene's index as a note."""
    for value in (outside(rule), rule.high * 2.0 if rule.high > 0 else rule.high + 1.0, math.nan, math.inf):
        scene = Scene(**{rule.name: value})
        with pytest.raises(ParameterError) as expected:
            CompiledPlant(scene, Settings(), library)
        with pytest.raises(ParameterError) as single:
            api.simulate(scene, 1.0, 0.1)
        assert str(single.value) == str(expected.value) and not getattr(single.value, "__notes__", None)
        scenes = [Scene()] * 3 + [scene, Scene(mu=-1.0)]  # the first bad scene is named
        with pytest.raises(ParameterError) as many:
            api.simulate_many(scenes, 1.0, 0.1)
        assert str(many.value) == str(expected.value) and many.value.__notes__ == ["in scene 3"]


def test_electrodes_and_settings_are_refused(library):
    for scene in (Scene(x_start=1.4999), Scene(x_start=-1.4999), Scene(R=0.1, x_start=0.1499)):
        with pytest.raises(ParameterError) as expected:
            CompiledPlant(scene, Settings(), library)
        with pytest.raises(ParameterError) as got:
            api.simulate_many({name: [getattr(scene, name)] for name in scene_names()}, 1.0, 0.1)
        assert str(got.value) == str(expected.value) and "x_start" in str(got.value)
    for settings, name in ((Settings(rtol=0.0), "rtol"), (Settings(fidelity=3), "fidelity"),
                           (Settings(kernel=1), "kernel"), (Settings(max_step=-1.0), "max_step")):
        with pytest.raises(ParameterError) as got:
            api.simulate(Scene(), 1.0, 0.1, settings)
        assert got.value.name == name
    with pytest.raises(ParameterError) as got:
        api.simulate_many({"tau": [1.0]}, 1.0, 0.1)
    assert got.value.name == "tau" and "unknown parameter" in str(got.value)


@pytest.mark.parametrize("stop_time, interval, name", [(1.0, 0.0, "interval"), (1.0, math.nan, "interval"),
                                                       (1.05, 0.1, "stop_time"), (0.0, 0.1, "stop_time"),
                                                       (math.inf, 0.1, "stop_time")])
def test_a_bad_grid_is_refused(stop_time, interval, name):
    with pytest.raises(ParameterError) as got:
        api.simulate(Scene(), stop_time, interval)
    assert got.value.name == name


def test_too_many_steps_per_interval_is_refused(library):
    """RK4 with max_step 1e-4 cannot make an interval of 1000 in 10^6 steps: plant.check_step's message."""
    settings = Settings(solver=Solver.RK4, max_step=1e-4)
    plant = CompiledPlant(Scene(), settings, library)
    with pytest.raises(ParameterError) as expected:
        plant.do_step(0.0, 1000.0, 0.0)
    with pytest.raises(ParameterError) as got:
        api.simulate(Scene(), 1000.0, 1000.0, settings)
    assert str(got.value) == str(expected.value)


def test_simulation_in_pieces_is_the_whole_run(library):
    whole = api.simulate(SCENES[1], 20.0, 0.1)
    simulation = api.Simulation(SCENES[1], interval=0.1, stop_time=20.0)
    pieces = [simulation.start, simulation.advance(1), simulation.advance(73), simulation.advance(126)]
    for name in api.OUTPUTS:
        assert np.array_equal(np.concatenate([getattr(p, name) for p in pieces]), getattr(whole, name)), name
    assert simulation.k == 200


def test_simulation_stays_stopped(library):
    simulation = api.Simulation(Scene(alpha=0.5, x_start=1.2), interval=0.1)
    first = simulation.advance(50)
    assert isinstance(first.error, TerminalEvent) and 0 < len(first.x) < 50
    again = simulation.advance(5)
    assert len(again.x) == 0 and again.error is first.error


@pytest.mark.parametrize("settings", [Settings(), Settings(rtol=1e-10, max_step=1000.0),
                                      Settings(solver=Solver.RK4, max_step=0.05)], ids=str)
def test_the_state_only_run_gives_the_same_x_and_v(settings):
    """outputs=STATE (core/plant.c vk_run_xv: no x'' or forces per point) steps as the full run: the same time, x
    and v to the bit, the same stop (pull-in in the last scene), the other outputs left out."""
    scenes = SCENES + [Scene(alpha=0.5, x_start=1.2)]
    full = api.simulate_many(scenes, 30.0, 0.1, settings)
    lean = api.simulate_many(scenes, 30.0, 0.1, settings, outputs=("x",))
    for name in api.STATE:
        assert np.array_equal(getattr(lean, name), getattr(full, name), equal_nan=True), name
    assert lean.a is None and lean.in_contact is None and lean.F_contact is None
    assert list(lean.n_points) == list(full.n_points) and lean.stopped == full.stopped and lean.stopped[-1]
    run = api.simulate(SCENES[1], 30.0, 0.1, settings, outputs=api.STATE)
    assert np.array_equal(run.x, full.run(1).x) and run.in_contact is None
    with pytest.raises(ParameterError) as got:
        api.simulate(Scene(), 1.0, 0.1, outputs=("x", "y"))
    assert got.value.name == "outputs" and "unknown output" in str(got.value)


@pytest.mark.parametrize("settings", [Settings(), Settings(rtol=1e-15), Settings(max_step=0.3),
                                      Settings(solver=Solver.RK4, max_step=0.05)], ids=str)
def test_one_scene_is_filled_as_simulate_many_fills_it(settings):
    """simulate's one-scene path (Python floats: scene_broken, fill_one) against simulate_many's numpy columns:
    the same kernel structure byte for byte, the same ceiling, warnings and notes, for scenes that take every
    branch (light damping: the tolerance factor; no forcing: no ceiling; each drive term alone; a fast drive:
    RK4's warning) and stop times that bound the factor or not (NaN: a Simulation without a stop time)."""
    checked, _ = checked_settings(Scene(), settings)  # as simulate checks its settings (api._settings)
    scenes = SCENES + [Scene(Delta=0.0, beta=0.01, gamma=0.0, alpha=0.0), Scene(beta=0.0, gamma=0.003),
                       Scene(Omega=40.0), Scene(mu=0.0)]
    for scene in scenes:
        for start, stop in ((0.0, 10.0), (0.0, 1e4), (5.0, math.nan)):
            many = np.zeros(1, dtype=api.PLANT_DTYPE)
            one, ceiling, warnings, notes = api.fill_one(scene, checked, start, stop)
            ceilings, many_warnings, many_notes = api.fill_plants(many, api.scene_columns([scene]), checked, start,
                                                                  stop)
            assert bytes(one) == many.tobytes(), (scene, start, stop)
            assert (ceiling, warnings, notes) == (ceilings[0], many_warnings[0], many_notes[0])
            assert not api.scene_broken(scene, int(checked.fidelity))


def test_one_scene_is_refused_and_stops_as_in_simulate_many(library):
    """scene_broken flags each rule's breach and the electrodes' as scenes_broken does, and a run that pulls in stops at
    the same point with the same message in simulate (one-scene path) and simulate_many."""
    for rule in (r for r in RULES if r.name in scene_names() and r.when is None):
        for value in (rule.low - 1.0, rule.high * 2.0 + 1.0, math.nan):
            scene = Scene(**{rule.name: value})
            assert api.scene_broken(scene, 0) == bool(api.scenes_broken(api.scene_columns([scene]), 0)[0]), (rule, value)
    for scene in (Scene(x_start=1.4995, R=1.0), Scene(x_start=-1.4995, R=1.0)):  # 1 -+ 2x/(3R) < 1e-3
        assert api.scene_broken(scene, 0) and api.scenes_broken(api.scene_columns([scene]), 0)[0]
    pull_in = Scene(alpha=0.5, x_start=1.2)
    one, many = api.simulate(pull_in, 5.0, 0.25), api.simulate_many([pull_in], 5.0, 0.25).run(0)
    assert one.stopped and one.stopped == many.stopped and isinstance(one.error, TerminalEvent)
    assert np.array_equal(one.x, many.x) and len(one.x) < 21
