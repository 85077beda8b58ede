"""Acceptance 1, 2, 5 of issue 5 on build/HertzEAClosedLoop.fmu and AdaptiveLyapunovController.fmu under FMPy:
the docs/model.md, Adaptive controller setup (paper example plant, exact Eq. 3, x(0) = 0.06, x'(0) = 0.01, wrong initial estimates,
reference x0 + X_f cos(w t - psi)), rtol 1e-10, tau in [0, 200], outputs every 0.1."""
import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from test_bad_input import initialise
from vibrofmu.hosts.run import run_fmu

STOP, H, RTOL = 200.0, 0.1, 1e-10


@pytest.fixture(scope="module")
def loop(closed_loop_fmu):
    def run(**values):
        result = run_fmu(closed_loop_fmu, values, STOP, H, tolerance=RTOL)
        assert result.completed, result.stop_reason
        return result.time, result.outputs

    return run


def test_both_fmus_validate_without_messages(closed_loop_fmu, controller_fmu):
    assert validate_fmu(str(closed_loop_fmu)) == []
    assert validate_fmu(str(controller_fmu)) == []


def test_acceptance_1_paper_corrected_errata_setup(loop):
    """V never rises between outputs (the integrator's error in V over one output interval is ~rtol*V = 1e-12,
    so 1e-12 is the test's own threshold); V' - Eq. 85 <= 1e-8 (it is lambda2 e2 times the Eq. 3 - Eq. 7 series
    remainder, ~1e-12); V(0) and V(200) as in docs/model.md, Adaptive controller's table (5 digits printed there)."""
    t, o = loop()
    assert np.max(np.diff(o["V"])) <= 1e-12
    assert np.max(np.abs(o["V_rate"] - o["V_rate_promised"])) <= 1e-8
    assert o["V"][0] == pytest.approx(1.01333e-2, rel=1e-5)
    assert o["V"][-1] == pytest.approx(8.4134e-3, rel=1e-5)
    # |e1| < 1e-4 for tau > 100 does NOT hold with the corrected gains (lambda1 = 4, c = 2): e1 settles to a forced
    # oscillation driven by -phi^T theta~ (the estimates converge far too slowly to remove it):
    # e1'' + c e1' + c^2 e1 = -phi^T theta~, |phi^T theta~| ~ |mu~ x~'| + |a1~ x~| ~ 7e-4 at w ~ 1, so
    # |e1| ~ 7e-4/|c^2 - w^2 + i c w| = 7e-4/3.6 = 1.9e-4. Asserted here so that the finding stays measured.
    late = np.abs(o["e1"][t > 100])
    assert 1.5e-4 < np.max(late) < 2.5e-4


def test_acceptance_1_e1_below_1e_4_with_lambda1_16(loop):
    """Same setup with lambda1 = 16 (c = 4): the forced e1 is 7e-4/|16 - 1 + 4i| = 4.5e-5 < 1e-4; V and V' as above."""
    t, o = loop(lambda1=16.0)
    assert np.max(np.abs(o["e1"][t > 100])) < 1e-4
    assert np.max(np.diff(o["V"])) <= 1e-12
    assert np.max(np.abs(o["V_rate"] - o["V_rate_promised"])) <= 1e-8


def test_damped_law_keeps_its_promise(loop):
    """the corrected better variant: V' = -lambda1 c e1^2 - lambda2 k e2^2; V(200) = 8.4061e-3 (docs/model.md, Adaptive controller)."""
    t, o = loop(law=1)
    assert np.max(np.diff(o["V"])) <= 1e-12
    assert np.max(np.abs(o["V_rate"] - o["V_rate_promised"])) <= 1e-8
    assert o["V"][-1] == pytest.approx(8.4061e-3, rel=1e-5)


def test_acceptance_2_paper_literal_lets_v_rise(loop):
    """Erratum (docs/model.md, Adaptive controller): with Eq. 78 and 81 as printed, V rises 1.0133e-2 -> 1.1308e-2 and V' - Eq. 85
    reaches 2.3e-4."""
    t, o = loop(law=2)
    assert np.max(np.diff(o["V"])) > 1e-6
    # 5 significant digits in docs/model.md: rounding <= 5e-5 relative, inside rel 1e-4
    assert o["V"][-1] == pytest.approx(1.1308e-2, rel=1e-4)
    assert np.max(np.abs(o["V_rate"] - o["V_rate_promised"])) > 1e-4


@pytest.mark.parametrize("which", ["controller", "closed_loop"])
@pytest.mark.parametrize("name,value", [("lambda1", 0.0), ("lambda2", -1.0), ("lambda7", math.nan),
                                        ("lambda11", math.inf), ("k_damping", 0.0), ("mu_hat_start", math.nan)])
def test_acceptance_5_bad_gains_give_fmi2error(controller_fmu, closed_loop_fmu, which, name, value):
    fmu = controller_fmu if which == "controller" else closed_loop_fmu
    with initialise(fmu, {name: value}) as instance:
        with pytest.raises(FMICallException) as failure:
            instance.fmu.exitInitializationMode()
        assert failure.value.status == 3
        assert f"parameter {name} = " in instance.log.errors()[-1]
        with pytest.raises(FMICallException):
            instance.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)


def test_controller_output_follows_its_inputs_and_estimates_hold_exactly(controller_fmu):
    """U is algebraic in the inputs (direct feedthrough); doStep integrates the estimates with the inputs held."""
    with initialise(controller_fmu, {}) as instance:
        instance.fmu.exitInitializationMode()
        U_ref = instance.value_references(["U"])
        before = instance.fmu.getReal(U_ref)[0]
        instance.set({"x": 0.05, "v": 0.01, "x_ref": 0.04})
        assert instance.fmu.getReal(U_ref)[0] != before
        instance.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.5)
        mu_hat = instance.fmu.getReal(instance.value_references(["mu_hat"]))[0]
        # mu^' = -(lambda2/lambda3) x2 e2 with x2 = 0.01, e2 = 0.01 + 2*0.01 = 0.03 held over 0.5: -1.5e-4
        assert mu_hat == pytest.approx(0.05 - 0.01 * 0.03 * 0.5, rel=1e-12)
