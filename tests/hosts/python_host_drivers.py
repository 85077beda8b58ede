"""Drivers of third-party Python FMI hosts, run as scripts by another interpreter (tests/hosts/test_python_hosts.py).

Each runs one FMU from 0 to STOP with communication step STEP and prints one JSON line
{"time": [...], "values": {output: [...]}} with the values after each step; standard library and the
host package only (no numpy: the interpreter may have none). argv: host, FMU path, stop, step, outputs...
"""
import json
import sys


def run_libcosimpy(fmu, stop, step, outputs):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.WARNING)  # its default prints FMI Library's debug lines; errors still show
    ns = round(step * 1e9)  # libcosim's time is integer nanoseconds: 0.1 exactly
    execution = CosimExecution.from_step_size(step_size=ns)
    slave = CosimLocalSlave(fmu_path=fmu, instance_name="m")
    index = execution.add_local_slave(local_slave=slave)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer=observer)
    refs = {v.name.decode(): v.reference for v in execution.slave_variables(index)}
    vrs = [refs[name] for name in outputs]
    n = round(stop / step)
    time, values = [], {name: [] for name in outputs}
    for i in range(1, n + 1):  # libcosim initialises in its first step: values after each step
        execution.step()
        time.append(i * ns * 1e-9)
        for name, value in zip(outputs, observer.last_real_values(slave_index=index, variable_references=vrs)):
            values[name].append(value)
    return time, values


def run_ecospy(fmu, stop, step, outputs):
    from ecospy import EcosSimulation, EcosSimulationStructure

    structure = EcosSimulationStructure()
    structure.add_model("m", fmu)
    time, values = [], {name: [] for name in outputs}
    with EcosSimulation(structure=structure, step_size=step) as sim:
        sim.init()
        for _ in range(round(stop / step)):
            sim.step()
            time.append(sim.get_time())
            for name in outputs:
                values[name].append(sim.get_real(f"m::{name}"))
    return time, values


if __name__ == "__main__":
    host, fmu, stop, step, *outputs = sys.argv[1:]
    run = {"libcosimpy": run_libcosimpy, "ecospy": run_ecospy}[host]
    time, values = run(fmu, float(stop), float(step), outputs)
    print(json.dumps({"time": time, "values": values}))
