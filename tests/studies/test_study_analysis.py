"""Issue 16: the averaged predictions the studies are compared with, checked against independent evidence."""
import math

import pytest
from scipy.integrate import solve_ivp

from vibromodel import averaging as av
from vibromodel.parameters import Scene
from vibromodel.slowflow import SlowFlowSolution
from vibrofmu.study.analysis import projection, slow_flow_cusp, stable_manifold, to_initial_state, wilson
from vibrofmu.study.scheduling import MAX_OVERHEAD, batch_size

BISTABLE = Scene(mu=0.002)


@pytest.fixture(scope="module")
def bistable():
    scene = BISTABLE.with_values(omega=av.averaged(BISTABLE).omega_e - 0.0024)
    model = av.averaged(scene)
    return scene, model, stable_manifold(scene, model, bound=0.8, with_times=True)


def test_the_stable_manifold_flows_into_the_saddle(bistable):
    """Points of the traced manifold, run forwards by the slow flow for the time they were traced back,
    return to where the trace started, 1e-7 from the saddle. Running forwards, an error off the manifold
    (rtol 1e-10 of the trace, ~3e-11 here) grows at most by exp(lambda_u t), lambda_u = 3.4e-4: by 1e3 over
    t = 20000, so the end lies within 1e-7 + 1e-7 of the saddle; 1e-6 leaves a 5x margin."""
    scene, model, branches = bistable
    flow = model.flow()
    saddle = next(s for s in av.steady_states(flow, model.r_max) if s.kind == "saddle")
    assert len(branches) == 2
    for times, branch in branches:
        far = 0
        for k in range(1, len(times), len(times) // 40):
            t_back = times[k]
            if t_back > 20000:
                break
            end = solve_ivp(lambda _t, z: flow.rhs(*z), (0, t_back), branch[k], method="DOP853", rtol=1e-11,
                            atol=1e-14).y[:, -1]
            assert math.hypot(end[0] - saddle.A, end[1] - saddle.B) < 1e-6
            far += math.hypot(branch[k][0] - saddle.A, branch[k][1] - saddle.B) > 0.05
        assert far >= 3  # the check covers points well away from the saddle


def test_the_boundary_map_inverts_the_averaged_models_initial_state(bistable):
    """to_initial_state maps (A, B) to (x0, v0); the averaged model (fidelity 3) picks its initial (A, B) from
    (x0, v0) by its own fixed-point iteration: the round trip returns (A, B) to ~1e-12 (the iteration's
    contraction stops at round-off)."""
    _, model, branches = bistable
    AB = branches[0][1][:: len(branches[0][1]) // 7]
    xv = to_initial_state(model, AB)
    solution = SlowFlowSolution(model, 0.0, float(xv[0, 0]), float(xv[0, 1]), 1e-8)
    for (A, B), (x0, v0) in zip(AB, xv):
        back = solution._initial_slow_state(0.0, float(x0), float(v0))
        assert back == pytest.approx((A, B), abs=1e-12)


@pytest.mark.long  # fold continuations to the cusp
def test_the_cusp_is_where_the_two_folds_meet():
    """Just above the bisected cusp the two folds exist and lie close together in omega (they are born
    together); just below there are none."""
    cusp = slow_flow_cusp(BISTABLE, 0.0004, 0.0009)
    lo, hi = cusp["bracket"]
    assert hi - lo < 1e-12
    above = av.folds(av.averaged(BISTABLE.with_values(Delta=hi * (1 + 1e-3))), samples=400)
    below = av.folds(av.averaged(BISTABLE.with_values(Delta=lo * (1 - 1e-3))), samples=400)
    assert len(above) == 2 and len(below) == 0
    width = above[1].omega - above[0].omega
    assert 0 < width < 1e-4  # the bistable band at 0.1 % above the cusp vs ~1.4e-3 at Delta = 0.0009


def test_wilson_interval():
    # k = 0: [0, z^2/(n + z^2)] (closed form of the Wilson bound at p = 0)
    z2 = 1.959963984540054**2
    assert wilson(0, 40) == pytest.approx([0.0, z2 / (40 + z2)], abs=1e-15)
    # symmetric about 1/2 for k = n/2, and k -> n - k mirrors it
    lo, hi = wilson(5, 10)
    assert lo + hi == pytest.approx(1.0, abs=1e-15)
    assert wilson(3, 10) == pytest.approx([1 - x for x in wilson(7, 10)[::-1]], abs=1e-15)
    assert (lo, hi) == pytest.approx((0.2366, 0.7634), abs=1e-4)  # Wilson (1927) / Newcombe (1998) tables


@pytest.mark.parametrize("c_s, c_w, remaining, workers", [(0.004, 0.02, 10000, 2), (0.004, 1.0, 100, 2),
                                                          (0.01, 0.001, 10**6, 64), (0.003, 0.1, 10**6, 64)])
def test_batch_size_keeps_scheduling_under_5_percent(c_s, c_w, remaining, workers):
    def fine(b):  # a worker's overhead <= 5 %, and the scheduler's task rate keeps every worker busy
        return c_s / (b * c_w) <= MAX_OVERHEAD and b / c_s >= workers / c_w

    b = batch_size(c_s, c_w, remaining, workers)
    assert fine(b)
    assert b == 1 or not fine(b - 1)  # the smallest such batch


def test_projection_is_bounded_by_workers_and_scheduler():
    run = {"case_cost_s_mean": 0.1, "scheduler_s_per_task": 0.002, "batch_size": 1}
    projected = projection(run, 64)
    p = projected["at_this_batch_size"]
    # the projection's formula recomputed from its inputs: one or two roundings; approx's default rel 1e-6
    assert p["worker_bound"] == pytest.approx(64 / 0.102)
    assert p["scheduler_bound"] == pytest.approx(500.0)
    assert p["cases_per_s"] == pytest.approx(500.0)  # b = 1: the scheduler is the bottleneck
    q = projected["at_the_batch_size_for_these_workers"]
    assert q["batch_size"] == 2  # 64 workers x 0.002 s / 0.1 s = 1.28 -> 2
    assert q["cases_per_s"] == pytest.approx(64 * 2 / (2 * 0.1 + 0.002))  # now the workers bound it


def test_batches_hold_at_most_a_checkpoint_of_work():
    """Issue 26: a basins study interrupted at 25 s kept 2 of 3,600 cases (its first batches held 450 cases each).
    Now no batch holds more than CHECKPOINT_S of work at the pilot's cost per case, unless the scheduling
    overhead needs more (the smallest size b wins); every case is in exactly one batch."""
    from vibrofmu.study.scheduling import CHECKPOINT_S, checkpoint_batch, guided_batches

    for c_w, smallest in ((0.05, 1), (6.0, 1), (0.001, 1), (0.05, 100)):
        sizes = guided_batches(3600, smallest, 2, checkpoint_batch(c_w))
        assert sum(sizes) == 3600
        assert max(sizes) <= max(smallest, CHECKPOINT_S / c_w)
    assert checkpoint_batch(0.0) is None and sum(guided_batches(3600, 1, 2, None)) == 3600
