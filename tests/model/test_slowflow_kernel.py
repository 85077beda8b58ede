"""Fidelity 3's table on the compiled kernel (core/slowflow_table.c, vibromodel.slowflow_kernel) against SciPy's.

The kernel integrates the slow flow with the core's DOP853 (scipy's tableau, error norm and dense output; the step
controller of integrate.py, PI where SciPy's is I), so the two tables are not the same bits. Each integrator keeps
every accepted step's local error estimate within rtol max(|y|, |y_new|) + atol <= the table's tolerance
rtol max|Z| + atol; the slow flow's field has divergence -mu <= 0 (its rotation nu(r) is area-preserving), so the
local errors add up without exponential growth, and a table's nodes lie within (steps) x (tolerance) of the exact slow
flow, here a reference at rtol 1e-13 (measured: 0.2-1 % of that bound for the kernel's table, 3-4 % for SciPy's, on
the scenes below). The Hermite cells are checked as the Python _hermite_cells makes them from the same node values.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vibrofmu.fmus.kernel import kernel_library
from vibromodel import slowflow, slowflow_kernel
from vibromodel.averaging import averaged
from vibromodel.parameters import Scene

SCENES = {"paper": Scene(), "detuned, strong drive": Scene(omega=1.05, Delta=0.02, mu=0.05),
          "no AC, light damping": Scene(beta=0.0, gamma=0.0, mu=0.01), "started at rest": Scene(x_start=0.0)}


@pytest.fixture(scope="module", autouse=True)
def kernel():
    kernel_library()  # compiled.load_library registers it (slowflow_kernel.use_kernel)
    assert slowflow_kernel.kernel_loaded()


def tables(scene, t_end=200.0, rtol=1e-8):
    model = averaged(scene)
    return [slowflow.SlowFlowSolution(model, 0.0, scene.x_start, scene.v_start, rtol, t_end=t_end, kernel=kernel)
            for kernel in (True, False)]


@pytest.mark.parametrize("name", list(SCENES))
def test_kernel_table_meets_the_tables_accuracy_against_a_reference(name):
    scene = SCENES[name]
    c_table, scipy_table = tables(scene)
    assert c_table.kernel and not scipy_table.kernel
    flow = c_table.flow
    Z0 = c_table._initial_slow_state(0.0, scene.x_start, scene.v_start)
    reference = solve_ivp(lambda _t, Z: flow.rhs(*Z), (0.0, c_table.t_end), Z0, method="DOP853", rtol=1e-13,
                          atol=1e-16, dense_output=True).sol
    steps = slowflow_kernel.tabulate(flow, 0.0, Z0, c_table.t_end, c_table.rtol, c_table.atol, math.inf, 0.0, 0,
                                     slowflow.MAX_REFINEMENTS, 10**6)[4]
    for table in (c_table, scipy_table):
        cells = table.cell_array()
        nodes = table.t0 + table.spacing * np.arange(len(cells))
        error = np.max(np.abs(cells[:, [0, 4]].T - reference(nodes)))
        assert error <= steps * table.tolerance, (table.kernel, error, steps, table.tolerance)
    # both refine the grid by the same rule, so the kernel's grid is never coarser than its tolerance allows
    assert c_table.spacing <= 1.0 and len(c_table.cells) * c_table.spacing == pytest.approx(c_table.t_end)


def test_kernel_cells_are_the_hermite_cells_of_their_nodes():
    c_table, _ = tables(Scene())
    cells = c_table.cell_array()
    Z = np.vstack([cells[:, [0, 4]], [c_table.Z_end]]).T  # the nodes' values, the last the end state's
    dZ = np.array(c_table.flow.rhs(*Z)) * c_table.spacing
    expected = np.stack([Z[:, :-1], dZ[:, :-1], 3 * (Z[:, 1:] - Z[:, :-1]) - 2 * dZ[:, :-1] - dZ[:, 1:],
                         2 * (Z[:, :-1] - Z[:, 1:]) + dZ[:, :-1] + dZ[:, 1:]]).transpose(2, 1, 0).reshape(-1, 8)
    # every cell but the last: the same operations on the same doubles (the last node is read at t0 + n spacing,
    # the end state at t0 + span: the same instant up to the rounding of n spacing)
    assert np.array_equal(cells[:-1], expected[:-1])


def test_a_grid_beyond_the_room_given_falls_back_to_scipy():
    c_table, scipy_table = tables(Scene())
    Z0 = c_table._initial_slow_state(0.0, Scene().x_start, Scene().v_start)
    assert slowflow_kernel.tabulate(c_table.flow, 0.0, Z0, 200.0, 1e-8, 1e-10, math.inf, 0.0, 0,
                                    slowflow.MAX_REFINEMENTS, len(c_table.cells) - 1) is None


def test_the_table_grows_on_the_kernel_as_the_run_advances():
    scene = Scene()
    c_table, scipy_table = tables(scene, t_end=None)
    for table in (c_table, scipy_table):
        table.state(650.0)  # beyond the first CHUNK: extended a CHUNK at a time on the first grid
    assert c_table.t_end == scipy_table.t_end and c_table.spacing == scipy_table.spacing
    # the extension's nodes meet the same accuracy as the first table's (see the module docstring): within the
    # tolerance per step summed over the steps of the whole run, both against each other through a reference
    # at rtol 1e-13
    flow = c_table.flow
    Z0 = c_table._initial_slow_state(0.0, scene.x_start, scene.v_start)
    reference = solve_ivp(lambda _t, Z: flow.rhs(*Z), (0.0, c_table.t_end), Z0, method="DOP853", rtol=1e-13,
                          atol=1e-16, dense_output=True).sol
    steps = slowflow_kernel.tabulate(flow, 0.0, Z0, c_table.t_end, c_table.rtol, c_table.atol, math.inf,
                                     c_table.spacing, len(c_table.cells), 1, 10**6)[4]
    cells = c_table.cell_array()
    nodes = c_table.t0 + c_table.spacing * np.arange(len(cells))
    assert np.max(np.abs(cells[:, [0, 4]].T - reference(nodes))) <= steps * c_table.tolerance


def test_the_front_ends_layout_is_the_headers():
    """slowflow_kernel's sizes of flow[], out[] and the message are core/slowflow_table.h's and dop853.h's."""
    import re

    from vibrofmu.fmus.kernel import CORE

    header = (CORE / "slowflow_table.h").read_text()

    def position(last):  # the value of an enum's last name: the count of the names before it
        names = re.search(r"enum \{([^}]*\b" + last + r")\s*\}", header).group(1).split(",")
        return [name.strip() for name in names].index(last)

    assert (slowflow_kernel.SF_FLOW, slowflow_kernel.ST_OUTPUTS) == (position("SF_FLOW"), position("ST_OUTPUTS"))
    assert re.search(r"#define DOP_MESSAGE (\d+)", (CORE / "dop853.h").read_text()).group(1) == \
        str(slowflow_kernel.MESSAGE)
    assert (slowflow_kernel.SR_SCENE, slowflow_kernel.SR_FILTER, slowflow_kernel.SR_OUTPUTS) == \
        (position("SR_SCENE"), 7, position("SR_OUTPUTS"))
    assert re.search(r"SR_P = 6, SR_FILTER \}", header)  # filter[]: three complex numbers and p
    assert re.search(r"#define SR_RESYNC 16\b", header)  # the rotations between resyncs, as the test above counts
    codes = re.search(r"enum \{ ST_OK = (\d), ST_CAPACITY = (\d), ST_FAILED = (\d) \}", header).groups()
    assert tuple(map(int, codes)) == (slowflow_kernel.ST_OK, slowflow_kernel.ST_CAPACITY, slowflow_kernel.ST_FAILED)


@pytest.mark.parametrize("name", list(SCENES))
def test_the_estimates_samples_on_the_kernel_match_numpys(name):
    """error_estimates.averaged_terms's residual and its propagation, in C (vk_slowflow_residual) and with numpy.

    Each sample's x~'' and accel are sums of terms of size <= S (below) evaluated at cosines and sines that differ
    from numpy's by the rotation's drift, <= SR_RESYNC rotations of <= 4 ulps each, and by the two libraries'
    rounding (<= 1 ulp): so |dR| <= 2 (4 SR_RESYNC + 1) eps S per sample, x~'' counted twice (its omega^2 and
    Omega^2 terms). The propagation sums the samples' differences with the gain of the recurrence, at most
    (|phi1| + |phi2|) / (p (1 - |step|)) (a geometric series of the step's modulus)."""
    from vibromodel import error_estimates

    scene = SCENES[name]
    c_table, _ = tables(scene)
    model = c_table.averaged
    on_kernel = error_estimates.averaged_terms(model, c_table, 200.0)
    c_table.kernel = False  # the same table, sampled with numpy
    with_numpy = error_estimates.averaged_terms(model, c_table, 200.0)
    eps, resync = np.finfo(float).eps, 16  # core/slowflow_table.h's SR_RESYNC
    r = float(np.max(np.hypot(c_table.cell_array()[:, 0], c_table.cell_array()[:, 4])))
    w2 = max(scene.omega, scene.Omega) ** 2
    size = 1.0 + abs(scene.Delta) + 4.0 * (abs(scene.alpha) + abs(scene.beta) + 2 * abs(scene.gamma)) + w2 * r + \
        w2 * (abs(scene.beta) + abs(scene.gamma)) / scene.Omega ** 2
    per_sample = 2 * (4 * resync + 1) * eps * size
    mu, k1 = scene.mu, model.eq.k[1]
    p = math.sqrt(k1 - 0.25 * mu * mu)
    n = int(min(error_estimates.RESIDUAL_SAMPLES, max(2, math.ceil(200.0 * max(2 * scene.omega, 2 * scene.Omega, p)
                                                                   / error_estimates.RESIDUAL_STEP_TURN) + 1)))
    lam, dt = complex(-0.5 * mu, p), 200.0 / (n - 1)
    step = np.exp(lam * dt)
    gain = (abs((step - 1.0) / lam) + abs((step - 1.0 - lam * dt) / (lam * lam * dt))) / (p * (1.0 - abs(step)))
    assert abs(on_kernel["residual"] - with_numpy["residual"]) <= per_sample
    assert abs(on_kernel["propagated"] - with_numpy["propagated"]) <= per_sample * gain
    assert on_kernel["amplitude"] == with_numpy["amplitude"]
