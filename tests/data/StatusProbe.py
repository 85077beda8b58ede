"""Tiny pythonfmu slave exercising the fmi2 status shim (see tests/fmus/test_status_shim.py).

Behaviour selected by the parameter ``p``:
  p < 0   exit_initialization_mode flags an error (fmi_status = 3)
  p == 5  do_step flags an error once t > 0.5
  p == 7  do_step returns False with fmi_status = 0 (plain discard)
  p == 9  do_step raises RuntimeError (pythonfmu's fatal path)
otherwise it runs normally, y = p * t.
"""
from pythonfmu import Fmi2Slave, Integer, Real
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability


class StatusProbe(Fmi2Slave):

    author = "vibrofmu"
    description = "Status shim probe"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.p = 1.0
        self.fmi_status = 0
        self.y = 0.0
        self.register_variable(Real("p", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.fixed))
        self.register_variable(Integer("fmi_status", causality=Fmi2Causality.local,
                                       variability=Fmi2Variability.discrete))
        self.register_variable(Real("y", causality=Fmi2Causality.output,
                                    variability=Fmi2Variability.continuous,
                                    initial=Fmi2Initial.exact))

    def exit_initialization_mode(self):
        if self.p < 0:
            self.log(f"parameter p must be >= 0, got p={self.p}", Fmi2Status.error)
            self.fmi_status = 3

    def do_step(self, current_time, step_size):
        t = current_time + step_size
        if self.p == 5 and t > 0.5:
            self.log(f"p=5: refusing to step beyond t={current_time}", Fmi2Status.error)
            self.fmi_status = 3
            return False
        if self.p == 7:
            return False
        if self.p == 9:
            raise RuntimeError("p=9: deliberate exception")
        self.y = self.p * t
        return True
