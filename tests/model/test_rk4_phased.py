"""RK4 with the drive's phasors by rotation (integrate.Rk4 with `phased`, the twin of core/rk4.c's
rk4_advance_phased): the phasors each stage receives are cos and sin of f t up to rounding, and the method keeps
order 4. (C == Python bit for bit on the plant: tests/core/test_plant_kernel.py's RK4 scenes run this path.)"""
import math

from vibromodel.integrate import PHASE_RESYNC, Rk4
from vibromodel.models import ExactModel
from vibromodel.parameters import Scene

EPS = 2.220446049250313e-16
U = EPS / 2  # unit roundoff


def test_stage_phasors_match_direct_cos_sin():
    scene = Scene()
    model = ExactModel(scene)
    frequencies = model.drive_frequencies
    seen = []

    def recording(t, phases, x, v, U_in):
        seen.append((t, list(phases)))
        return model.accel_phased(t, phases, x, v, U_in)

    ig = Rk4(model.accel, model.events, 0.0, scene.x_start, scene.v_start, 0.0, 0.01,
             phased=(frequencies, recording))
    t = 0.0
    for _ in range(40):  # output interval 5: 500 steps per advance, so the resync every PHASE_RESYNC steps matters
        t += 5.0
        ig.advance(t)
    worst = 0.0
    for ts, phases in seen:
        for k, f in enumerate(frequencies):
            worst = max(worst, abs(phases[2 * k] - math.cos(f * ts)), abs(phases[2 * k + 1] - math.sin(f * ts)))
    # Bound: each rotation c' = c rc - s rs adds <= 4u per component (two products and a sum, each <= u of a
    # term <= 1, and the rotation's own cos/sin of f h/2, <= 1 ulp = 2u); 2 rotations per step, at most
    # PHASE_RESYNC steps between direct evaluations. The direct side cos(f * ts) carries the rounding of ts
    # (= t + h/2 or t + h, <= u |ts|) and of the product f ts (<= u |f ts|): <= 2u |f ts| in the angle.
    f_t_max = max(frequencies) * t
    assert worst <= (4 * 2 * PHASE_RESYNC + 2 * f_t_max + 4) * U, worst
    assert worst > 0.0  # the rotations are in use (direct evaluation would give exactly 0)


def forced(t, x, v, U_in, w=1.7):
    return -x + math.cos(w * t)


def test_phased_rk4_is_fourth_order_on_a_forced_oscillator():
    """x'' = -x + cos(w t), x(0) = x'(0) = 0: x = (cos w t - cos t) / (1 - w^2). Halving h cuts the error at T by
    2^p with p -> 4; the rotations change rounding only, so the phased x(T) equals the direct RK4's to 1e-12
    (the forcing differs by <= ~3e-14 per stage, previous test; integrated over T = 10 that moves x by <= 3e-13)
    and the observed orders approach 4 (last one within 0.06: the next error term is O(h^5), relative size ~h)."""
    w, T = 1.7, 10.0

    def phased(t, phases, x, v, U_in):
        return -x + phases[0]

    def error(h, phased_on):
        ig = Rk4(forced, (), 0.0, 0.0, 0.0, 0.0, h, phased=((w,), phased) if phased_on else None)
        ig.advance(T)
        return abs(ig.x - (math.cos(w * T) - math.cos(T)) / (1.0 - w * w))

    steps = (0.04, 0.02, 0.01)
    errors = [error(h, True) for h in steps]
    direct = [error(h, False) for h in steps]
    assert all(abs(a - b) <= 1e-12 for a, b in zip(errors, direct)), (errors, direct)
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    assert orders[0] < orders[1] <= 4.01 and abs(orders[1] - 4.0) < 0.06, (errors, orders)


def test_phased_and_direct_rk4_agree_to_rounding():
    """The same RK4 with the drive evaluated directly at every stage: the two differ by the phasors' rounding
    only, <= delta = (128 + 2 * 800) u = 1.9e-13 per stage (previous test's bound at tau = 200, f = 2 Omega = 4).
    The damped plant (mu = 0.1, linearised stiffness ~1.5) turns a forcing perturbation delta into at most
    delta times its resonant gain 1 / (mu omega_0) ~ 8: |dx| <= 1.6e-12; asserted 2e-12 (observed ~5e-17)."""
    scene = Scene()
    model = ExactModel(scene)
    a = Rk4(model.accel, model.events, 0.0, scene.x_start, scene.v_start, 0.0, 0.01)
    b = Rk4(model.accel, model.events, 0.0, scene.x_start, scene.v_start, 0.0, 0.01,
            phased=(model.drive_frequencies, model.accel_phased))
    worst = scale = 0.0
    for i in range(1, 2001):
        a.advance(0.1 * i)
        b.advance(0.1 * i)
        worst, scale = max(worst, abs(a.x - b.x)), max(scale, abs(a.x))
    assert worst <= 2e-12, worst
    assert scale > 0.01
