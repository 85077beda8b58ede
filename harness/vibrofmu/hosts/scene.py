"""Co-simulation scenes: the FMUs in order with their parameters, the connections, H, the stop time, the ordering
and the tolerance (`CosimScene`), read from TOML or JSON files (`read_scene`) and checked, each problem a
SceneError naming it. The master that runs a scene is cosim.py; SSP files are ssp.py.
"""
from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from fmpy import read_model_description

ORDERINGS = ("gauss-seidel", "jacobi", "fmpy")
SCENE_KEYS = {"stop_time", "step", "ordering", "tolerance", "connections", "fmu"}
FMU_KEYS = {"name", "path", "parameters"}


class SceneError(ValueError):
    """A scene file that cannot be run; the message names the file and the problem."""


@dataclass(frozen=True)
class FmuSpec:
    name: str
    path: Path
    parameters: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Connection:
    source: str  # FMU name
    output: str
    target: str
    input: str


@dataclass(frozen=True)
class CosimScene:
    fmus: tuple[FmuSpec, ...]
    connections: tuple[Connection, ...]
    step: float
    stop_time: float
    ordering: str = "gauss-seidel"
    tolerance: float | None = None

    def with_settings(self, step: float | None = None, ordering: str | None = None,
                      stop_time: float | None = None) -> "CosimScene":
        scene = replace(self, step=step or self.step, ordering=ordering or self.ordering,
                        stop_time=stop_time or self.stop_time)
        check_numbers(scene, "settings")
        return scene


def parse_scene(data: dict, scene_dir: Path, fmu_dir: Path) -> CosimScene:
    if not isinstance(data, dict):
        raise SceneError("the scene must be a table (TOML) or an object (JSON)")
    _no_unknown(data, SCENE_KEYS, "the scene")
    for key in ("fmu", "connections", "step", "stop_time"):
        if key not in data:
            raise SceneError(f"missing '{key}'")
    fmus = tuple(fmu_spec(i, entry, scene_dir, fmu_dir) for i, entry in enumerate(_list(data, "fmu")))
    names = [spec.name for spec in fmus]
    if len(set(names)) != len(names):
        raise SceneError(f"FMU names must be unique: {names}")
    connections = tuple(_connection(text, names) for text in _list(data, "connections"))
    scene = CosimScene(fmus=fmus, connections=connections, step=_number(data, "step"),
                       stop_time=_number(data, "stop_time"), ordering=data.get("ordering", "gauss-seidel"),
                       tolerance=_number(data, "tolerance") if "tolerance" in data else None)
    check_numbers(scene, "the scene")
    return scene


def check_numbers(scene: CosimScene, where: str) -> None:
    for key in ("step", "stop_time"):
        value = getattr(scene, key)
        if not (math.isfinite(value) and value > 0):
            raise SceneError(f"{where}: '{key}' = {value!r} must be a finite number > 0")
    if scene.ordering not in ORDERINGS:
        raise SceneError(f"{where}: 'ordering' = {scene.ordering!r}; known: {', '.join(ORDERINGS)}")
    if scene.tolerance is not None and not (math.isfinite(scene.tolerance) and scene.tolerance > 0):
        raise SceneError(f"{where}: 'tolerance' = {scene.tolerance!r} must be a finite number > 0")


def _no_unknown(table: dict, known: set, where: str) -> None:
    unknown = sorted(set(table) - known)
    if unknown:
        raise SceneError(f"unknown key '{unknown[0]}' in {where}; known: {', '.join(sorted(known))}")


def _list(data: dict, key: str) -> list:
    value = data[key]
    if not isinstance(value, list) or not value:
        raise SceneError(f"'{key}' must be a non-empty list")
    return value


def _number(data: dict, key: str) -> float:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"'{key}' = {value!r} must be a number")
    return float(value)


def fmu_spec(index: int, entry, scene_dir: Path, fmu_dir: Path) -> FmuSpec:
    where = f"fmu #{index + 1}"
    if not isinstance(entry, dict):
        raise SceneError(f"{where} must be a table with name, path, parameters")
    _no_unknown(entry, FMU_KEYS, where)
    for key in ("name", "path"):
        if not isinstance(entry.get(key), str) or not entry[key]:
            raise SceneError(f"{where}: '{key}' must be a non-empty string")
    name = entry["name"]
    candidates = [Path(entry["path"])] if Path(entry["path"]).is_absolute() else \
        [scene_dir / entry["path"], fmu_dir / entry["path"]]
    path = next((p for p in candidates if p.is_file()), None)
    if path is None:
        raise SceneError(f"FMU '{name}': no file {entry['path']} (looked in {', '.join(str(p) for p in candidates)};"
                         " `vibrofmu build` writes the FMUs to build/)")
    parameters = entry.get("parameters", {})
    if not isinstance(parameters, dict):
        raise SceneError(f"FMU '{name}': 'parameters' must be a table")
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
    for key, value in parameters.items():
        if key not in variables or variables[key].causality not in ("parameter", "input"):
            raise SceneError(f"FMU '{name}': '{key}' is not a parameter of {path.name}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"FMU '{name}': parameter {key} = {value!r} must be a number")
    return FmuSpec(name=name, path=path, parameters=dict(parameters))


def _connection(text, names: list[str]) -> Connection:
    """'source.output -> target.input'."""
    if not isinstance(text, str) or text.count("->") != 1:
        raise SceneError(f"connection {text!r} must read 'source.output -> target.input'")
    ends = []
    for end in (part.strip() for part in text.split("->")):
        fmu, dot, variable = end.partition(".")
        if not dot or not variable:
            raise SceneError(f"connection {text!r}: '{end}' must read 'fmu.variable'")
        if fmu not in names:
            raise SceneError(f"connection {text!r}: no FMU named '{fmu}' (FMUs: {', '.join(names)})")
        ends.append((fmu, variable))
    return Connection(*ends[0], *ends[1])


def scene_fmu(scene: CosimScene, name: str) -> FmuSpec:
    return next(spec for spec in scene.fmus if spec.name == name)


def read_scene(path: Path | str, fmu_dir: Path) -> CosimScene:
    """Read a TOML (.toml) or JSON scene. Relative FMU paths are resolved against the scene file's folder first,
    then against fmu_dir (the build folder)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise SceneError(f"scene {path}: cannot read it ({error.strerror})") from None
    try:
        data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as error:
        raise SceneError(f"scene {path}: not valid {'TOML' if path.suffix == '.toml' else 'JSON'}: {error}") from None
    try:
        scene = parse_scene(data, path.parent, fmu_dir)
    except SceneError as error:
        raise SceneError(f"scene {path}: {error}") from None
    return scene
