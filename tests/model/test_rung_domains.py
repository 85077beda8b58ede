"""Every rung answers inside its domain or refuses (issue 25): the polynomial fidelities stop at pull-in like the
exact one; the averaged (3) and analytic (4) rungs check their own validity at set-up."""
import math

import pytest

from vibrofmu.fmus import kernel
from vibromodel.integrate import TerminalEvent
from vibromodel.parameters import PULL_IN_GAP, Scene
from vibromodel.plant import Kernel, Settings, make_plant

PULL_IN_WORDS = "pull-in: {side} gap 1 {sign} 2x/(3R) below 0.001 at tau = "


@pytest.fixture(scope="module")
def library():
    return kernel.kernel_library(), "the test's kernel"


def run_to_stop(plant, h=0.1, n=500):
    """Steps of h until an exception; returns (the largest |x| returned, the exception)."""
    largest = 0.0
    for i in range(n):
        try:
            largest = max(largest, abs(plant.do_step(i * h, h, 0.0).x))
        except TerminalEvent as stop:
            return largest, stop
    return largest, None


@pytest.mark.parametrize("kernel_kind", [Kernel.COMPILED, Kernel.PYTHON])
@pytest.mark.parametrize("fidelity", [1, 2])
@pytest.mark.parametrize("scene, side, sign", [(Scene(Delta=0.3), "lower", "+"), (Scene(beta=3.0), "upper", "-"),
                                               (Scene(v_start=-3.0), "lower", "+")])
def test_polynomial_fidelities_stop_at_pull_in_like_the_exact_one(library, kernel_kind, fidelity, scene, side, sign):
    """Fidelities 1 and 2 used to run past the electrodes (|x| up to 34.6 with fmi2OK). They now stop at the exact
    model's pull-in events: the same words, the stop on the gap PULL_IN_GAP, every returned |x| below 3R/2."""
    settings = Settings(fidelity=fidelity, kernel=kernel_kind)
    largest, stop = run_to_stop(make_plant(scene, settings, 0.0, 50.0, library=library))
    _, exact_stop = run_to_stop(make_plant(scene, Settings(kernel=kernel_kind), 0.0, 50.0, library=library))
    assert stop is not None and exact_stop is not None
    assert str(stop).startswith(PULL_IN_WORDS.format(side=side, sign=sign))
    assert str(exact_stop).startswith(PULL_IN_WORDS.format(side=side, sign=sign))
    # the event is located on the dense output to brentq's xtol 1e-15 in tau; x there is within rtol-sized
    # rounding of the gap's x, (1 - PULL_IN_GAP) 3R/2: 1e-6 relative is far above both and far below the gap (1e-3)
    assert abs(stop.x) == pytest.approx((1.0 - PULL_IN_GAP) * 1.5 * scene.R, rel=1e-6)
    assert largest < 1.5 * scene.R


def test_polynomial_pull_in_is_the_same_in_python_and_c(library):
    """The C kernel's message names the same gap as Python's event (its events are indexed differently)."""
    stops = [run_to_stop(make_plant(Scene(Delta=0.3), Settings(fidelity=1, kernel=k), 0.0, 50.0, library=library))[1]
             for k in (Kernel.COMPILED, Kernel.PYTHON)]
    assert str(stops[0]) == str(stops[1]) and math.isfinite(stops[0].t)
