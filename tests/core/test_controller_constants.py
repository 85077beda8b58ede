"""The controller's constants have one C derivation, core/controller.c's vk_controller_constants, used by the native FMUs
(native/controller_setup.c) and the pythonfmu FMUs' compiled models (compiled_loop.fill_controller); it gives
the bits of control.Controller, the pure-Python twin."""
import struct

import pytest

from vibrofmu.fmus import kernel
from vibromodel import core_layouts
from vibromodel.compiled_loop import declare, fill_controller
from vibromodel.control import Controller, Gains, Law
from vibromodel.parameters import Scene
from vibromodel.plant import TIME_TOLERANCE


@pytest.fixture(scope="module")
def library():
    library = kernel.kernel_library()
    assert declare(library) is None
    return library


def bits(values):
    return [struct.pack("<d", float(value)) for value in values]


SCENES = [Scene(), Scene(mu=0.3, Delta=-0.01, omega=1.7, Omega=0.45, alpha=0.004, beta=2e-4, gamma=3e-5, R=0.8)]
GAINS = [Gains(), Gains(lambdas=(2.5, 0.3, 1e-5, 7.0, 3e-3, 0.2, 11.0, 0.9, 1.3e2, 4e-2, 6.5), k_damping=0.7)]


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("gains", GAINS)
@pytest.mark.parametrize("law", list(Law))
def test_vc_constants_gives_the_bits_of_control_controller(library, scene, gains, law):
    """Bit identity is free: vk_controller_constants does control.Controller's operations in the same order (copies, one
    division per adaptation gain, sqrt(l1/l2), -(l1 ** 1.5)/sqrt(l2) with the same libm pow and sqrt)."""
    controller = Controller(scene, gains, law)
    c = core_layouts.VcController()
    fill_controller(c, controller, scene, library)
    assert bits(c.g3) == bits(controller.phi.g3)
    assert bits(c.theta) == bits(controller.theta)
    for name, regressor in (("phi", controller.phi), ("phi_update", controller.phi_update)):
        filled = getattr(c, name)
        assert bits([filled.w_delta, filled.delta_sign, filled.w_beta, filled.w_gamma]) == \
            bits([regressor.w_delta, regressor.delta_sign, regressor.w_beta, regressor.w_gamma]), name
    assert bits(c.Lambda) == bits(controller.Lambda)
    assert bits(c.adaptation) == bits(controller.adaptation)
    assert bits([c.l1, c.l2, c.c, c.k_damping, c.promised_e1, c.true_delta, c.time_tolerance]) == \
        bits([controller.l1, controller.l2, controller.c, gains.k_damping, controller.promised_e1, scene.Delta,
              TIME_TOLERANCE])
    assert c.law == int(law)
    # the state, inputs and outputs are not constants: vk_controller_constants leaves them as they were (zero here)
    assert c.t == 0.0 and not any(c.theta_hat) and not any(c.out) and c.enabled == 0
