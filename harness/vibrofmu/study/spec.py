"""What a study computes: its kind, base scene, grids, tolerances and settings, from the kind's defaults,
then a TOML file (--spec), then --set NAME=VALUE. Every mistake raises SpecError (one line, exit 2).

TOML layout (every table optional; see docs/studies.md):

    kind = "basins"            # must match the command line's KIND when given
    engine = "core"            # fmu | core
    [scene]                    # base values of any scene parameter (mu, Delta, omega, ...)
    mu = 0.002
    [grid]                     # axes [lo, hi, n] (response-map: omega_offset, Delta; basins: x0, v0)
    A = [-0.5, 0.5, 60]
    [tolerances]               # monte-carlo: NAME = {distribution = "uniform"|"normal", relative = 0.05}
    mu = {distribution = "normal", relative = 0.05}
    [settings]                 # samples, seed (monte-carlo); sigma (basins)
    samples = 400
"""
from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from vibromodel.parameters import ParameterError, Scene, scene_names, validate

KINDS = ("response-map", "basins", "monte-carlo")
DISTRIBUTIONS = ("uniform", "normal")


class SpecError(ValueError):
    """A bad study specification or an unusable cluster: the message is the one error line."""


@dataclass
class Spec:
    kind: str
    engine: str = "fmu"
    scene: dict = field(default_factory=dict)  # overrides of Scene's defaults
    grid: dict = field(default_factory=dict)  # axis -> [lo, hi, n]
    tolerances: dict = field(default_factory=dict)  # parameter -> {"distribution": ..., "relative": ...}
    settings: dict = field(default_factory=dict)

    def base_scene(self) -> Scene:
        return Scene().with_values(**self.scene)

    def axis(self, name: str) -> list[float]:
        lo, hi, n = self.grid[name]
        n = int(n)
        return [lo] if n == 1 else [lo + (hi - lo) * i / (n - 1) for i in range(n)]

    def as_dict(self) -> dict:
        return {"kind": self.kind, "engine": self.engine, "scene": self.scene, "grid": self.grid,
                "tolerances": self.tolerances, "settings": self.settings}

    def digest(self) -> str:
        """Identifies what the cases are (the engine is not part of it: both give the same rows)."""
        content = {k: v for k, v in self.as_dict().items() if k != "engine"}
        # the cusp test runs after the cases and is not stored with them: it does not change what they are
        content["settings"] = {k: v for k, v in self.settings.items() if not k.startswith("cusp_test")}
        return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:16]


# mu = 0.002: the bistable scene of the stability study (tests/studies/test_stability.py, docs/model.md, Averaging and slow flow)
DEFAULTS = {
    "response-map": dict(scene={"mu": 0.002},
                         # omega = omega_e + offset; the slow flow's cusp lies near Delta = 0.00055 and its
                         # bistable band widens to omega_e - [0.0042, 0.0027] at Delta = 0.0009
                         grid={"omega_offset": [-0.0050, -0.0010, 41], "Delta": [0.0004, 0.0009, 11]}),
    "basins": dict(scene={"mu": 0.002}, settings={"sigma": -0.0024},
                   # initial states: x(0) = x0, x'(0) = v0
                   grid={"x0": [-0.5, 0.5, 60], "v0": [-0.5, 0.5, 60]}),
    "monte-carlo": dict(scene={}, settings={"samples": 400, "seed": 2026},
                        tolerances={name: {"distribution": "uniform", "relative": 0.05}
                                    for name in ("mu", "alpha", "R", "Delta")}),
}
QUICK = {
    "response-map": dict(grid={"omega_offset": [-0.0045, -0.0015, 13], "Delta": [0.0004, 0.0009, 3]}),
    "basins": dict(grid={"x0": [-0.5, 0.5, 8], "v0": [-0.5, 0.5, 8]}),
    "monte-carlo": dict(settings={"samples": 40}),
}
GRID_AXES = {"response-map": ("omega_offset", "Delta"), "basins": ("x0", "v0"), "monte-carlo": ()}
SETTING_NAMES = {"response-map": ("cusp_test", "cusp_test_periods"), "basins": ("sigma",), "monte-carlo": ("samples", "seed")}


def _merge(spec: Spec, table: dict) -> None:
    for key in ("scene", "grid", "tolerances", "settings"):
        getattr(spec, key).update(table.get(key, {}))
    if "engine" in table:
        spec.engine = table["engine"]


def build_spec(kind: str, spec_file: str | None = None, sets: list[str] = (), quick: bool = False,
               engine: str | None = None) -> Spec:
    if kind not in KINDS:
        raise SpecError(f"unknown study kind {kind!r}; known: {', '.join(KINDS)}")
    spec = Spec(kind)
    _merge(spec, json.loads(json.dumps(DEFAULTS[kind])))
    if quick:
        _merge(spec, QUICK[kind])
    if spec_file:
        try:
            table = tomllib.loads(Path(spec_file).read_text())
        except OSError as error:
            raise SpecError(f"cannot read spec {spec_file}: {error.strerror}") from None
        except tomllib.TOMLDecodeError as error:
            raise SpecError(f"spec {spec_file} is not valid TOML: {error}") from None
        unknown = set(table) - {"kind", "engine", "scene", "grid", "tolerances", "settings"}
        if unknown:
            raise SpecError(f"spec {spec_file}: unknown table or key {sorted(unknown)[0]!r}")
        if table.get("kind", kind) != kind:
            raise SpecError(f"spec {spec_file} is for kind {table['kind']!r}, not {kind!r}")
        _merge(spec, table)
    for item in sets:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep:
            raise SpecError(f"--set {item!r}: expected NAME=VALUE")
        try:
            value = float(text)
        except ValueError:
            raise SpecError(f"--set {name}: {text!r} is not a number") from None
        if name in SETTING_NAMES[kind]:
            spec.settings[name] = value
        else:
            spec.scene[name] = value
    if engine is not None:
        spec.engine = engine
    check(spec)
    return spec


def check(spec: Spec) -> None:
    """SpecError for the first thing that makes no sense."""
    kind = spec.kind
    if spec.engine not in ("fmu", "core"):
        raise SpecError(f"engine {spec.engine!r}: must be fmu or core")
    names = scene_names()
    for name, value in spec.scene.items():
        if name not in names:
            raise SpecError(f"unknown parameter {name!r}; known: {', '.join(names + list(SETTING_NAMES[kind]))}")
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise SpecError(f"parameter {name} = {value!r}: must be a finite number")
    try:
        validate(spec.base_scene())
    except ParameterError as error:
        raise SpecError(str(error)) from None
    for name, value in spec.settings.items():
        if name not in SETTING_NAMES[kind]:
            raise SpecError(f"unknown setting {name!r} for {kind}; known: {', '.join(SETTING_NAMES[kind]) or 'none'}")
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise SpecError(f"setting {name} = {value!r}: must be a finite number")
    for name, axis in spec.grid.items():
        if name not in GRID_AXES[kind]:
            raise SpecError(f"unknown grid axis {name!r} for {kind}; known: {', '.join(GRID_AXES[kind]) or 'none'}")
        if not (isinstance(axis, list) and len(axis) == 3 and all(isinstance(v, (int, float)) for v in axis)
                and all(math.isfinite(v) for v in axis)):
            raise SpecError(f"grid axis {name} = {axis!r}: must be [lo, hi, n] with finite numbers")
        lo, hi, n = axis
        if n != int(n) or n < 1:
            raise SpecError(f"grid axis {name} = {axis!r}: empty grid (n must be a whole number >= 1)")
        if hi < lo:
            raise SpecError(f"grid axis {name} = {axis!r}: empty grid (hi < lo)")
    if kind == "response-map" and spec.grid["Delta"][0] < 0:
        raise SpecError(f"grid axis Delta = {spec.grid['Delta']!r}: Delta must be >= 0")
    if kind == "response-map":
        if spec.settings.get("cusp_test", 0) not in (0, 1):
            raise SpecError(f"setting cusp_test = {spec.settings['cusp_test']!r}: must be 0 or 1")
        periods = spec.settings.get("cusp_test_periods", 1)
        if periods != int(periods) or periods < 1:
            raise SpecError(f"setting cusp_test_periods = {periods!r}: must be a whole number >= 1")
    if kind == "monte-carlo":
        samples = spec.settings["samples"]
        if samples != int(samples) or samples < 1:
            raise SpecError(f"setting samples = {samples!r}: empty study (must be a whole number >= 1)")
        if spec.settings["seed"] != int(spec.settings["seed"]):
            raise SpecError(f"setting seed = {spec.settings['seed']!r}: must be a whole number")
        for name, tolerance in spec.tolerances.items():
            if name not in names:
                raise SpecError(f"tolerance for unknown parameter {name!r}; known: {', '.join(names)}")
            if not isinstance(tolerance, dict) or set(tolerance) != {"distribution", "relative"}:
                raise SpecError(f"tolerance {name} = {tolerance!r}: must be {{distribution = ..., relative = ...}}")
            if tolerance["distribution"] not in DISTRIBUTIONS:
                raise SpecError(f"tolerance {name}: distribution {tolerance['distribution']!r} must be one of "
                                f"{', '.join(DISTRIBUTIONS)}")
            relative = tolerance["relative"]
            if not isinstance(relative, (int, float)) or not math.isfinite(relative) or relative < 0:
                raise SpecError(f"tolerance {name}: relative = {relative!r} must be a finite number >= 0")
