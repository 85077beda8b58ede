"""What the FMI 2.0 Model Exchange tests of the native FMUs share (FMPy's FMU2Model and FMU2Slave)."""
import ctypes

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model, FMU2Slave


def model_exchange_instance(fmu_path, tmp_path, log):
    """(modelDescription, unzipped folder, an instantiated Model Exchange instance logging to `log`, an FmuLog)."""
    md = read_model_description(str(fmu_path))
    folder = extract(str(fmu_path), str(tmp_path / "u"))
    fmu = FMU2Model(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="me")
    fmu.instantiate(callbacks=log.callbacks)
    return md, folder, fmu


def restart(fmu, continuous_time: bool = False) -> None:
    """Reset and initialise `fmu` again (an Error of the instance ends it): event mode, or continuous-time mode."""
    fmu.reset()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    if continuous_time:
        fmu.newDiscreteStates()
        fmu.enterContinuousTimeMode()


def assert_co_simulation_has_no_derivatives(md, folder, log, n: int) -> None:
    """A Co-Simulation instance of the same FMU, initialised, answers fmi2GetDerivatives of n states with an error."""
    cs = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                   instanceName="cs")
    cs.instantiate(callbacks=log.callbacks)
    cs.setupExperiment(startTime=0.0)
    cs.enterInitializationMode()
    cs.exitInitializationMode()
    assert cs.dll.fmi2GetDerivatives(ctypes.c_void_p(cs.component), (ctypes.c_double * n)(), n) > 0
    cs.freeInstance()
