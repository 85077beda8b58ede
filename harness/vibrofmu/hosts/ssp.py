"""Co-simulation scenes as SSP files (System Structure and Parameterization, SSP 1.0).

An `.ssp` is a zip archive with `SystemStructure.ssd` (the system: its components, their connectors,
parameter values and connections) and the FMUs it uses under `resources/`. Any SSP tool can read it;
FMPy simulates it with `fmpy.ssp.simulation.simulate_ssp`, and the project's master (`cosim.py`) runs it
with `vibrofmu closed-loop --mode cosim --scene FILE.ssp`.

What goes where in the SSD:
- every FMU of the scene is a `Component` (`source="resources/<file>.fmu"`), with a connector for each
  of its outputs and each connected input, and its parameter values inline as a `ParameterBinding`
  (`ssv:Real` / `ssv:Integer`);
- the scene's tolerance becomes the `rtol` parameter of every component that has one: FMPy's
  `simulate_ssp` calls `setupExperiment` without a tolerance, and the FMUs then use `rtol`, so both
  masters integrate with the same tolerance;
- stop time in `DefaultExperiment`; the communication step and the ordering, which SSP 1.0 has no
  element for, in an annotation of type `org.vibrofmu.cosim`.

FMPy 0.3.32's `simulate_ssp` does not apply the SSD's parameter bindings itself (it takes a
`parameter_set` argument instead): `fmpy_parameter_set` builds that set from the bindings, so that
`simulate_with_fmpy` runs the file with exactly the values it contains.
"""
from __future__ import annotations

import math
import tempfile
import zipfile
from pathlib import Path

from vibrofmu.fmus.archive import normalize_entries, publish, staging
from vibrofmu.hosts.scene import (Connection, CosimScene, FmuSpec, SceneError, check_numbers, fmu_spec,
                                  read_scene)

ANNOTATION = "org.vibrofmu.cosim"
SSD_NAME = "SystemStructure.ssd"
NAMESPACES = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
}
SSP_TYPES = {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean", "Enumeration": "Integer"}


def quoteattr(text: str) -> str:
    """An XML attribute value in double quotes (xml.sax.saxutils.quoteattr without its urllib import)."""
    from html import escape

    return '"' + escape(str(text), quote=True) + '"'


def _variables(fmu: Path) -> dict:
    from fmpy import read_model_description

    return {v.name: v for v in read_model_description(str(fmu)).modelVariables}


def _parameters_with_tolerance(spec: FmuSpec, variables: dict, tolerance: float | None) -> dict:
    values = dict(spec.parameters)
    if tolerance is not None and "rtol" in variables and "rtol" not in values:
        values["rtol"] = tolerance
    return values


def _number(value, kind: str) -> str:
    return str(int(value)) if kind == "Integer" else repr(float(value))


def scene_to_ssd(scene: CosimScene, name: str = "closed_loop") -> str:
    """The SystemStructure.ssd text of a scene (components in the scene's order)."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<ssd:SystemStructureDescription xmlns:ssd="{NAMESPACES["ssd"]}" xmlns:ssc="{NAMESPACES["ssc"]}" '
             f'xmlns:ssv="{NAMESPACES["ssv"]}" version="1.0" name={quoteattr(name)} generationTool="vibrofmu">',
             f'  <ssd:System name={quoteattr(name)}>',
             '    <ssd:Elements>']
    for spec in scene.fmus:
        variables = _variables(spec.path)
        lines.append(f'      <ssd:Component name={quoteattr(spec.name)} type="application/x-fmu-sharedlibrary" '
                     f'source={quoteattr("resources/" + spec.path.name)}>')
        lines.append('        <ssd:Connectors>')
        connected = {c.input for c in scene.connections if c.target == spec.name}
        for v in variables.values():
            # only connected inputs: FMPy 0.3.32's get_connections fails on (or, worse, silently miswires) an
            # input connector that no connection drives
            if (v.causality == "output" or v.name in connected) and v.type in SSP_TYPES:
                lines.append(f'          <ssd:Connector name={quoteattr(v.name)} kind="{v.causality}">'
                             f'<ssc:{SSP_TYPES[v.type]}/></ssd:Connector>')
        lines.append('        </ssd:Connectors>')
        values = _parameters_with_tolerance(spec, variables, scene.tolerance)
        if values:
            lines += ['        <ssd:ParameterBindings>', '          <ssd:ParameterBinding>',
                      '            <ssd:ParameterValues>',
                      f'              <ssv:ParameterSet version="1.0" name={quoteattr(spec.name)}>',
                      '                <ssv:Parameters>']
            for key, value in values.items():
                kind = SSP_TYPES.get(variables[key].type, "Real")
                lines.append(f'                  <ssv:Parameter name={quoteattr(key)}>'
                             f'<ssv:{kind} value="{_number(value, kind)}"/></ssv:Parameter>')
            lines += ['                </ssv:Parameters>', '              </ssv:ParameterSet>',
                      '            </ssd:ParameterValues>', '          </ssd:ParameterBinding>',
                      '        </ssd:ParameterBindings>']
        lines.append('      </ssd:Component>')
    lines.append('    </ssd:Elements>')
    lines.append('    <ssd:Connections>')
    for c in scene.connections:
        lines.append(f'      <ssd:Connection startElement={quoteattr(c.source)} startConnector={quoteattr(c.output)} '
                     f'endElement={quoteattr(c.target)} endConnector={quoteattr(c.input)}/>')
    lines.append('    </ssd:Connections>')
    lines.append('  </ssd:System>')
    tolerance = "" if scene.tolerance is None else f' tolerance="{scene.tolerance!r}"'
    lines += [f'  <ssd:DefaultExperiment startTime="0.0" stopTime="{scene.stop_time!r}">',
              '    <ssd:Annotations>',
              f'      <ssc:Annotation type="{ANNOTATION}">',
              f'        <cosim xmlns="urn:vibrofmu:cosim" step="{scene.step!r}" ordering="{scene.ordering}"{tolerance}/>',
              '      </ssc:Annotation>',
              '    </ssd:Annotations>',
              '  </ssd:DefaultExperiment>',
              '</ssd:SystemStructureDescription>', '']
    return "\n".join(lines)


def write_ssp(scene: CosimScene, path: Path, name: str = "closed_loop") -> Path:
    """Write the scene as an .ssp archive: the SSD and every FMU it uses (each file once)."""
    path = Path(path)
    with staging(path.parent) as stage:  # assembled beside path, moved to its name when complete
        staged = stage / path.name
        with zipfile.ZipFile(staged, "w", compression=zipfile.ZIP_DEFLATED) as archive:
            archive.writestr(SSD_NAME, scene_to_ssd(scene, name))
            for fmu in dict.fromkeys(spec.path for spec in scene.fmus):
                archive.write(fmu, f"resources/{fmu.name}")
        normalize_entries(staged)
        staged.chmod(0o644)
        return publish(staged, path)


def load_ssp(path: Path | str, unzip_dir: Path | None = None) -> CosimScene:
    """Read an .ssp into a scene of the project's master. The FMUs are extracted to unzip_dir (default: a
    new temporary folder that lives as long as the process). Raises SceneError naming the problem."""
    from fmpy.ssp.ssd import Component, read_ssd


    path = Path(path)
    try:
        ssd = read_ssd(str(path))
    except Exception as error:  # zip, XML or schema errors: FMPy raises plain Exception
        raise SceneError(f"scene {path}: not a valid SSP file: {str(error).splitlines()[0]}") from None
    unzip_dir = Path(unzip_dir or tempfile.mkdtemp(prefix="vibrofmu_ssp_"))
    with zipfile.ZipFile(path) as archive:
        archive.extractall(unzip_dir)
    fmus = []
    for element in ssd.system.elements:
        if not isinstance(element, Component):
            raise SceneError(f"scene {path}: only components at the top level are supported ({element.name})")
        values = {}
        for binding in element.parameterBindings:
            for parameter_set in binding.parameterValues:
                for p in parameter_set.parameters:
                    values[p.name] = int(p.value) if p.type == "Integer" else float(p.value)
        fmu = unzip_dir / (element.source or "")
        if not element.source or not fmu.is_file():
            raise SceneError(f"scene {path}: component '{element.name}': no FMU {element.source!r} in the archive")
        try:  # the same checks as a TOML scene's: parameters exist and are numbers
            fmus.append(fmu_spec(len(fmus), {"name": element.name, "path": str(fmu), "parameters": values},
                                  unzip_dir, unzip_dir))
        except SceneError as error:
            raise SceneError(f"scene {path}: {error}") from None
    connections = tuple(Connection(c.startElement, c.startConnector, c.endElement, c.endConnector)
                        for c in ssd.system.connections)
    settings = _annotation(path)
    scene = CosimScene(fmus=tuple(fmus), connections=connections, step=settings["step"],
                       stop_time=settings["stop_time"], ordering=settings["ordering"],
                       tolerance=settings.get("tolerance"))
    check_numbers(scene, f"scene {path}")
    return scene


def _annotation(path: Path) -> dict:
    """Stop time (DefaultExperiment) and the cosim annotation's step, ordering, tolerance."""
    import xml.etree.ElementTree as ET


    with zipfile.ZipFile(path) as archive:
        root = ET.fromstring(archive.read(SSD_NAME))
    experiment = root.find("ssd:DefaultExperiment", NAMESPACES)
    if experiment is None or experiment.get("stopTime") is None:
        raise SceneError(f"scene {path}: no DefaultExperiment with a stopTime")
    settings = {"stop_time": float(experiment.get("stopTime"))}
    cosim = experiment.find(f"ssd:Annotations/ssc:Annotation[@type='{ANNOTATION}']/{{urn:vibrofmu:cosim}}cosim",
                            NAMESPACES)
    if cosim is None:
        raise SceneError(f"scene {path}: no {ANNOTATION} annotation with the communication step")
    settings["step"] = float(cosim.get("step"))
    settings["ordering"] = cosim.get("ordering", "gauss-seidel")
    if cosim.get("tolerance") is not None:
        settings["tolerance"] = float(cosim.get("tolerance"))
    return settings


def fmpy_parameter_set(path: Path | str):
    """The SSD's parameter bindings as the `parameter_set` FMPy's simulate_ssp takes ('component.name')."""
    from fmpy.ssp.ssd import Parameter, ParameterSet, read_ssd

    ssd = read_ssd(str(path))
    result = ParameterSet(name="bindings")
    for element in ssd.system.elements:
        for binding in getattr(element, "parameterBindings", []):
            for parameter_set in binding.parameterValues:
                for p in parameter_set.parameters:
                    result.parameters.append(Parameter(name=f"{element.name}.{p.name}", type=p.type, value=p.value))
    return result


def simulate_with_fmpy(path: Path | str, step: float | None = None, stop_time: float | None = None) -> dict:
    """Run the .ssp with FMPy's simulate_ssp at the file's (or the given) step and stop time.

    Returns {"time": t_1 ... t_N, "connector": values}: FMPy labels each row with the time at the start of
    the step, but its values are those after the step, so the times here are shifted by one step to the
    time the values belong to."""
    import numpy as np
    from fmpy.ssp.simulation import simulate_ssp

    settings = _annotation(Path(path))
    H = step or settings["step"]
    stop = stop_time or settings["stop_time"]
    rows = simulate_ssp(str(path), start_time=0.0, stop_time=stop, step_size=H,
                        parameter_set=fmpy_parameter_set(path))
    names = [n for n in rows.dtype.names if n != "time"]
    return {"time": rows["time"] + H, **{n: np.asarray(rows[n], dtype=float) for n in names}}


def write_scene_ssps(scene_files, fmu_dir: Path, out_dir: Path) -> list[Path]:
    """Each TOML/JSON scene as out_dir/<stem>.ssp (the FMUs from fmu_dir)."""

    written = []
    for scene_file in scene_files:
        scene = read_scene(scene_file, fmu_dir)
        written.append(write_ssp(scene, Path(out_dir) / f"{Path(scene_file).stem}.ssp", Path(scene_file).stem))
    return written


def max_difference(a: dict, b: dict, columns) -> dict:
    """max |a - b| per column over the common length (both sampled at the same communication points)."""
    import numpy as np

    out = {}
    for column in columns:
        n = min(len(a[column]), len(b[column]))
        d = np.abs(np.asarray(a[column][:n], float) - np.asarray(b[column][:n], float))
        out[column] = float(np.max(d)) if n else math.nan
    return out
