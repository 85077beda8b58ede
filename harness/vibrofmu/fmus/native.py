"""Native FMUs: the pythonfmu FMUs' interface on C code only (fmu_src/native/), no Python at run time.

`build_native(pythonfmu_fmu, out_dir)` writes out_dir/<id>.fmu with
  modelDescription.xml      the pythonfmu FMU's (same variables, value references, start values, default
                            experiment) with the native capabilities and the source files;
  binaries/linux64/<id>.so  gcc;
  binaries/win64/<id>.dll   x86_64-w64-mingw32-gcc (Debian's mingw-w64), when installed;
  sources/                  every C file and header, flat, and buildDescription.xml (fmpy.build.
                            build_platform_binary compiles them for the host's platform);
  documentation/            the reference result of the default experiment (refresult.pack_reference).

These headers are generated here (with state_fields.h and the closed loop's reference.h), at build time, and packed in sources/:
  variables.h  the variable table, from the pythonfmu FMU's modelDescription.xml;
  rules.h      the parameter rules' constants and fixed messages, taken from vibromodel (parameters.py,
               plant.py, ...) by evaluating its checks, so that the native FMU logs what the Python slaves log;
  rule_index.h each rule's parameter (and its condition's) as a value reference of this model;
The fidelity registry's header fmu_src/core/fidelity.h (generated from vibromodel.fidelities and committed,
vibrofmu.fmus.kernel) is packed with the core's files: the native models branch on its properties of a level.
"""
from __future__ import annotations

import math
import re
import shutil
import string
import subprocess
import threading
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from vibromodel.messages import TEXTS

from vibrofmu import paths
from vibrofmu.fmus import compilers, toolchain
from vibrofmu.fmus.kernel import check_fidelity_header
from vibrofmu.fmus.state_fields import state_fields_header

_FMPY = threading.Lock()  # build_native's reference simulation, when native FMUs are built side by side
FMU_SRC = paths.FMU_SRC  # a checkout's fmu_src/ or the installed package's copy
NATIVE_SRC = FMU_SRC / "native"
FMI_SRC = FMU_SRC / "fmi"  # the FMI 2.0 layer shared with the status shim
# The FMI standard's own headers (fmi2Functions.h ...) are not packed: an importing tool has them (FMI 2.0,
# section 2.1.2), FMPy's build_platform_binary compiles against its package's copy, and so does this build
# (toolchain.fmi_include_dir).
COMMON_SOURCES = (NATIVE_SRC / "fmi2_native.c", NATIVE_SRC / "fmi2_me.c", FMI_SRC / "fmi2_layer.c", NATIVE_SRC / "pytext.c",
                  NATIVE_SRC / "scene_checks.c", NATIVE_SRC / "series.c", FMU_SRC / "core" / "pyfloat.c",
                  NATIVE_SRC / "state_checks.c")
COMMON_HEADERS = (NATIVE_SRC / "fmi2_native.h", NATIVE_SRC / "me_model.h", NATIVE_SRC / "me_data.h",
                  FMI_SRC / "fmi2_layer.h", FMI_SRC / "fmi2_calls.h",
                  NATIVE_SRC / "pytext.h", NATIVE_SRC / "scene_checks.h", NATIVE_SRC / "series.h",
                  FMU_SRC / "core" / "pyfloat.h", NATIVE_SRC / "state_checks.h")
CORE = FMU_SRC / "core"


def solver_files() -> tuple[Path, ...]:
    """The compiled core's solvers: the interface core/solver.h with its table solver.c (and the event search
    roots.c, the DOP853 tableau) and each solver of its VK_SOLVER_LIST, X(<file>): core/<file>.c with <file>.h
    where there is one. A solver added to the list is packed without an entry here."""
    listed = re.search(r"#define VK_SOLVER_LIST\(X\)(.*)", (CORE / "solver.h").read_text()).group(1)
    names = re.findall(r"X\((\w+)\)", listed)
    files = [CORE / f"{name}{ext}" for name in names for ext in (".c", ".h")]
    return tuple(CORE / name for name in ("solver.c", "solver.h", "roots.c", "roots.h", "dop853_tableau.h")) + tuple(
        path for path in files if path.suffix == ".c" or path.is_file())


# the plant's set-up with the error estimate it computes by the core's estimate.c (the Python kernel path's)
PLANT_SETUP = (NATIVE_SRC / "plant_setup.c", NATIVE_SRC / "plant_setup.h", CORE / "estimate.c", CORE / "estimate.h")
# what each model needs beyond its folder's native_model.c and config.h
MODEL_FILES = {
    "HertzEAOscillator": tuple(CORE / name for name in ("plant.c", "plant.h", "model.c", "model.h", "fidelity.h"))
    + solver_files() + PLANT_SETUP,
    "AdaptiveLyapunovController": (CORE / "controller.c", CORE / "controller.h",
                                   NATIVE_SRC / "controller_setup.c", NATIVE_SRC / "controller_setup.h"),
    "HertzEAClosedLoop": tuple(CORE / name for name in (
        "closedloop.c", "closedloop.h", "controller.c", "controller.h", "oafm_eval.c", "oafm_eval.h", "plant.c",
        "plant.h", "model.c", "model.h", "fidelity.h")) + solver_files() + PLANT_SETUP + tuple(
            NATIVE_SRC / name for name in ("controller_setup.c", "controller_setup.h")),
}
# Model Exchange (fmu_src/native/fmi2_me.c, me_model.h): each model whose config.h defines ME_N_STATES, with its
# continuous states and each one's derivative variable, in the order of the C hooks' arrays, and the number of its
# event indicators (ME_N_INDICATORS) with their names (FMI 3.0 declares them as variables).
# A derivative variable the pythonfmu FMU does not have (der(NAME)) is added to the native FMU's variables after
# the pythonfmu FMU's (value references N, N + 1, ...; with_derivative_variables).
ESTIMATES = ("mu_hat", "a1_hat", "a2_hat", "a3_hat", "a4_hat", "a5_hat", "Delta_hat", "beta_hat", "gamma_hat")
ME_STATES = {"HertzEAOscillator": (("x", "v"), ("v", "a")),
             "AdaptiveLyapunovController": (ESTIMATES, tuple(f"der({e})" for e in ESTIMATES)),
             "HertzEAClosedLoop": (("x", "v", *ESTIMATES), ("v", "der(v)", *(f"der({e})" for e in ESTIMATES)))}
_INDICATORS = (
    ("contact_indicator", "1 + 2x/3: > 0 in contact (contact loss and re-contact at its zeros)"),
    ("upper_gap_indicator", "pull-in margin of the upper electrode, 1 - gap - 2x/(3R) (pull-in at 0)"),
    ("lower_gap_indicator", "pull-in margin of the lower electrode, 1 - gap + 2x/(3R) (pull-in at 0)"))
ME_INDICATORS = {"HertzEAOscillator": _INDICATORS, "AdaptiveLyapunovController": (),  # smooth: no events
                 "HertzEAClosedLoop": _INDICATORS}
# FMI 3.0 co-simulation with early return at contact loss and re-contact (config.h: HAS_EARLY_RETURN)
EARLY_RETURN = ("HertzEAOscillator",)
# fmi2/3GetDirectionalDerivative (config.h: HAS_DIRECTIONAL_DERIVATIVES)
DIRECTIONAL_DERIVATIVES = ("HertzEAOscillator",)


def with_derivative_variables(model_description: bytes) -> bytes:
    """The pythonfmu FMU's modelDescription.xml with the Model Exchange derivative variables it lacks (local,
    continuous, value references from N on, in ME_STATES' order); unchanged for a model without Model Exchange."""
    root = ET.fromstring(model_description)
    model_id = root.find("CoSimulation").get("modelIdentifier")
    if model_id not in ME_STATES:
        return model_description
    variables = root.find("ModelVariables")
    present = {sv.get("name") for sv in variables}
    vr = len(list(variables))
    for state, derivative in zip(*ME_STATES[model_id]):
        if derivative in present:
            continue
        sv = ET.SubElement(variables, "ScalarVariable", name=derivative, valueReference=str(vr), causality="local",
                           variability="continuous", description=f"time derivative of {state} (Model Exchange)")
        ET.SubElement(sv, "Real", unit="1")
        vr += 1
    return ET.tostring(root, encoding="utf-8")

# The compiler commands (vibrofmu.fmus.toolchain: NATIVE_LINUX64 with $CC, NATIVE_WIN64 with mingw-w64).
LINUX_COMMAND = ("gcc", *toolchain.NATIVE_LINUX64)
WIN64_COMMAND = (toolchain.WIN64_COMPILER, *toolchain.NATIVE_WIN64)

_TYPES = {"Real": "T_REAL", "Integer": "T_INTEGER", "Boolean": "T_BOOLEAN"}
_CAUSALITIES = {"parameter": "C_PARAMETER", "input": "C_INPUT", "output": "C_OUTPUT", "local": "C_LOCAL"}


def _c_double(value: float) -> str:
    if math.isinf(value):
        return "INFINITY" if value > 0 else "-INFINITY"
    return repr(float(value))


def _c_name(name: str) -> str:
    """A variable's name as a C identifier (der(v): der_v_)."""
    return re.sub(r"\W", "_", name)


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def variables_header(model_description: bytes) -> str:
    """variables.h: N_VARIABLES, VR_<name> and VARIABLES[] (by value reference, which must run 0..N-1)."""
    root = ET.fromstring(model_description)
    rows = []
    for sv in root.iter("ScalarVariable"):
        kind = next(child for child in sv if child.tag in _TYPES)
        causality = sv.get("causality", "local")
        variability = sv.get("variability", "continuous")
        initial = sv.get("initial")
        settable = causality == "parameter" or initial in ("exact", "approx")
        start = kind.get("start")
        value = {"true": 1.0, "false": 0.0}.get(start, None) if kind.tag == "Boolean" else None
        if value is None:
            value = float(start) if start is not None else 0.0
        rows.append((int(sv.get("valueReference")), sv.get("name"), kind.tag, causality, variability, settable, value))
    rows.sort()
    if [row[0] for row in rows] != list(range(len(rows))):
        raise ValueError("the native FMU layer needs value references 0..N-1")
    lines = ["/* variables.h -- generated by harness/vibrofmu/fmus/native.py from the pythonfmu FMU's modelDescription.xml;",
             " * do not edit. */", "#ifndef VARIABLES_H", "#define VARIABLES_H", "", "#include <math.h>", "",
             f"#define N_VARIABLES {len(rows)}",
             f"#define FMU_GUID {_c_string(root.get('guid') or '')}  /* fmi2Instantiate checks it */"]
    lines += [f"#define VR_{_c_name(name)} {vr}" for vr, name, *_ in rows]
    lines += ["", "static const VariableInfo VARIABLES[N_VARIABLES] = {"]
    lines += [f"    {{{_c_string(name)}, {_TYPES[kind]}, {_CAUSALITIES[causality]}, {_c_string(variability)}, "
              f"{int(settable)}, {_c_double(value)}}},"
              for vr, name, kind, causality, variability, settable, value in rows]
    lines += ["};", "", "#endif", ""]
    return "\n".join(lines)


def printf_format(template: str) -> str:
    """A vibromodel.messages template as a printf format: its text with % doubled, {field:spec} as %spec for the
    specs g, .Ng, .Nf, {field} as %s; ValueError for another spec or a conversion (!r)."""
    parts = []
    for literal, field, spec, conversion in string.Formatter().parse(template):
        parts.append(literal.replace("%", "%%"))
        if field is None:
            continue
        if conversion is not None or not re.fullmatch(r"(\.\d+)?[gf]|", spec):
            raise ValueError(f"{template!r}: the field {{{field}}} has no printf form (specs g, .Ng, .Nf or none)")
        parts.append(f"%{spec}" if spec else "%s")
    return "".join(parts)


def rules_header() -> str:
    """rules.h: vibromodel.parameters' table of valid ranges (rules_as_records, in checking order, each with the
    refusal text Rule.refusal gives), the constants the models' own checks use, and the scene's names and
    defaults -- all taken from vibromodel, so that the native FMUs check and word what the Python slaves do."""
    from vibromodel import error_estimates, integrate, models, parameters, plant
    from vibromodel.parameters import RULES, Scene, model_parameter_names, rules_as_records, scene_names

    constants = {
        "PULL_IN_GAP": parameters.PULL_IN_GAP, "MIN_RTOL": parameters.MIN_RTOL,
        "MAX_STEPS_PER_DOSTEP": float(plant.MAX_STEPS_PER_DOSTEP), "TIME_TOLERANCE": plant.TIME_TOLERANCE,
        "ATOL_PER_RTOL": integrate.ATOL_PER_RTOL, "RK4_DEFAULT_STEP": plant.RK4_DEFAULT_STEP,
        "RK4_DRIVE_THETA": integrate.RK4_DRIVE_THETA, "RK4_DRIVE_ERROR": integrate.RK4_DRIVE_ERROR,
        "ERROR_MEMORY_REFERENCE": models.ERROR_MEMORY_REFERENCE, "TOLERANCE_FACTOR_FLOOR": models.TOLERANCE_FACTOR_FLOOR,
        "CALIBRATION_TRUNCATION": error_estimates.CALIBRATION["truncation"],
        "DEFAULT_SPAN": error_estimates.DEFAULT_SPAN,
    }
    counts = {"ESTIMATE_COMPENSATED": int(error_estimates.NATIVE_COMPENSATED)}
    texts = {
        "STEP_SIZE": _reason(plant.check_step, 0.0, 0.0, 0.0, 0.0, math.inf),
        "INPUT": _reason(plant.check_step, 0.0, 0.0, 1.0, math.nan, math.inf),
    }
    rows = []
    for rule, record in zip(RULES, rules_as_records()):
        when = record["when"]
        when_values = [float(v) for v in when["values"]] if when else []
        text = rule.refusal(math.nan)  # describe(); reason: the text of every refusal of this rule
        rows.append(f"    {{{_c_string(record['name'])}, {_c_double(record['low'])}, {_c_double(record['high'])}, "
                    f"{int(record['low_inclusive'])}, {int(record['high_inclusive'])}, {int(record['integer'])}, "
                    f"{int(record['automatic'] is not None)}, {_c_double(record['automatic'] or 0.0)}, "
                    f"{_c_string(when['name']) if when else 'NULL'}, {len(when_values)}, "
                    f"{{{', '.join(map(_c_double, when_values)) or '0'}}}, {_c_string(text)}}},")
    defaults = Scene()
    lines = ["/* rules.h -- generated by harness/vibrofmu/fmus/native.py from vibromodel (parameters.RULES and the",
             " * constants of its checks); do not edit.  The native FMUs' checks use it, so that their messages",
             " * are the Python slaves'. */", "#ifndef RULES_H", "#define RULES_H", "", "#include <stddef.h>", ""]
    lines += [f"#define RULE_{name} {_c_double(value)}" for name, value in constants.items()]
    lines += [f"#define RULE_{name} {int(value)}" for name, value in counts.items()]
    lines += [f"#define RULE_{name} {_c_string(text)}" for name, text in texts.items()]
    lines += ["/* core/estimate.h's constants[] (error_estimates.kernel_constants), an initialiser */",
              "#define RULE_ESTIMATE_CONSTANTS {" + ", ".join(map(_c_double, error_estimates.kernel_constants())) + "}"]
    lines += [f"#define RULE_TEXT_{name} {_c_string(printf_format(template))}" for name, template in TEXTS.items()]
    lines += ["", "/* vibromodel.parameters.Rule: a finite number (whole for `integer`) in [low, high] (ends open where",
              " * not inclusive), or exactly `automatic`; only when parameter `when` has one of `when_values`. */",
              "typedef struct {", "    const char *name;", "    double low, high;",
              "    int low_inclusive, high_inclusive, integer, has_automatic;", "    double automatic;",
              "    const char *when;", "    int n_when;", "    double when_values[8];",
              "    const char *text; /* Rule.refusal's text */", "} VibroRule;", "",
              f"#define N_RULES {len(rows)}", "static const VibroRule RULES[N_RULES] = {", *rows, "};", "",
              "/* the scene's parameters in vibromodel.parameters.scene_names() order (a list for an initialiser), and",
              " * their defaults; X(name) for each parameter of the equation of motion (model_parameter_names()):",
              " * core/model.h's VkModel has a field of that name, which the native set-up copies from the variable */",
              f"#define SCENE_SIZE {len(scene_names())}",
              "#define SCENE_NAMES " + ", ".join(_c_string(name) for name in scene_names()),
              "#define SCENE_DEFAULTS {" + ", ".join(_c_double(getattr(defaults, n)) for n in scene_names()) + "}",
              "#define SCENE_MODEL_FIELDS(X) " + " ".join(f"X({name})" for name in model_parameter_names()),
              "", *auto_rows(), "", "#endif", ""]
    return "\n".join(lines)


def rule_index_header(model_description: bytes) -> str:
    """rule_index.h: for each rule of rules.h (in its order) the value reference of the parameter it checks and of
    the parameter its condition names (`when`), -1 where the model has no such parameter -- the lookup the checks
    at initialisation and at every state restore made by name (a string comparison per variable and rule)."""
    from vibromodel.parameters import rules_as_records

    root = ET.fromstring(model_description)
    parameters: dict[str, int] = {}
    for sv in root.iter("ScalarVariable"):  # the lowest value reference of a name, as a search of VARIABLES finds
        if sv.get("causality") == "parameter":
            vr = int(sv.get("valueReference"))
            parameters[sv.get("name")] = min(vr, parameters.get(sv.get("name"), vr))
    records = rules_as_records()
    vrs = [parameters.get(record["name"], -1) for record in records]
    whens = [parameters.get(record["when"]["name"], -1) if record["when"] else -1 for record in records]
    lines = ["/* rule_index.h -- generated by harness/vibrofmu/fmus/native.py from the modelDescription.xml and",
             " * vibromodel.parameters.RULES; do not edit. */", "#ifndef RULE_INDEX_H", "#define RULE_INDEX_H", "",
             f"#define N_RULE_INDEX {len(records)}  /* N_RULES */",
             "/* the value reference of RULES[r].name's parameter, -1 if the model has none */",
             "static const int RULE_VR[N_RULE_INDEX] = {" + ", ".join(map(str, vrs)) + "};",
             "/* the value reference of RULES[r].when's parameter, -1 if none (or no condition) */",
             "static const int RULE_WHEN_VR[N_RULE_INDEX] = {" + ", ".join(map(str, whens)) + "};", "", "#endif", ""]
    return "\n".join(lines)


def auto_rows() -> list[str]:
    """rules.h's part of fidelity auto (vibromodel.auto): its `fidelity` value and its candidates in its order (cheapest
    first), each the level, solver, rtol and cost the native plant's model_initialise walks as auto.choose does."""
    from vibromodel import auto, fidelities
    from vibromodel.plant import Settings

    rows = [f"    {{{int(c.fidelity)}, {int(c.solver)}, {_c_double(c.rtol)}, {_c_double(cost)}}},"
            for cost, c in auto.candidates(Settings())]
    return ["/* fidelity auto (vibromodel.auto.candidates, cheapest first): level, solver, rtol, cost per output */",
            f"#define RULE_AUTO_FIDELITY ({fidelities.AUTO})",
            f"#define RULE_AUTO_NEEDS_PYTHON {_c_string(fidelities.NATIVE_NEEDS_PYTHON)}",
            "typedef struct {", "    int fidelity, solver;", "    double rtol, cost;", "} AutoCandidate;",
            f"#define N_AUTO_CANDIDATES {len(rows)}", "static const AutoCandidate AUTO_CANDIDATES[N_AUTO_CANDIDATES] = {",
            *rows, "};"]


# The closed loop's references the native FMU carries: the kinds whose set-up (vibromodel.tracking.make_reference)
# is a closed form of these parameters (tracking.errata_terms: mu, a1 of alpha, gamma, R; Delta, omega; the free
# part's x~(0), x~'(0)) and of the start time (the piece starts there). The OAFM reference (kind 0) also depends on
# the stop time and its fit; it is not packed.
PACKED_REFERENCE_KINDS = (1, 2)
REFERENCE_DEPENDS = ("reference", "mu", "alpha", "gamma", "R", "Delta", "omega", "x_ref_start", "v_ref_start")


def reference_header() -> str:
    """reference.h: for each kind of PACKED_REFERENCE_KINDS, the reference's OeSolution (compiled_open_loop.
    OafmProgram of tracking.make_reference at the closed-loop FMU's defaults) as constant tables, with the
    values of REFERENCE_DEPENDS and the start time it holds for. Doubles as C hexadecimal literals (exact)."""
    from vibromodel.closedloop import ERRATA_SCENE
    from vibromodel.compiled_open_loop import OafmProgram, oafm_hints
    from vibromodel.plant import DEFAULT_EXPERIMENT
    from vibromodel.tracking import ReferenceSettings, make_reference

    t0 = float(DEFAULT_EXPERIMENT[0])
    lines = ["/* reference.h -- generated by harness/vibrofmu/fmus/native.py (vibromodel.tracking.make_reference and",
             " * compiled_open_loop.OafmProgram at the closed-loop FMU's defaults); do not edit. */",
             "#ifndef REFERENCE_H", "#define REFERENCE_H", "", '#include "oafm_eval.h"', "",
             "typedef struct {", "    int kind;                 /* the parameter `reference` */",
             "    double start_time;        /* the experiment's start time it holds for */",
             "    int n_depends;", "    unsigned depends[16];     /* value references of the parameters it depends on */",
             "    double values[16];        /* their values */", "    int64_t n_pieces;", "    const OePiece *pieces;",
             "    const char *note;", "} PackedReference;", ""]
    entries = []
    hexd = lambda v: float(v).hex() if math.isfinite(v) else _c_double(v)  # noqa: E731
    for kind in PACKED_REFERENCE_KINDS:
        settings = ReferenceSettings(kind=kind)
        solution, note = make_reference(ERRATA_SCENE, settings, t0)
        program = OafmProgram(solution, *oafm_hints(ERRATA_SCENE))
        if program.reason is not None:
            raise RuntimeError(f"reference kind {kind}: {program.reason}")
        pieces = []
        for i in range(program.struct.n_pieces):
            p = program.array[i]
            name = f"REF{kind}_P{i}"
            n_terms = p.group_end[p.n_groups - 1] if p.n_groups else 0
            arrays = {"decay_chain": (p.decay_chain, 4 * p.n_decay_rows, "int64_t"),
                      "freq_chain": (p.freq_chain, 4 * p.n_freq_rows, "int64_t"),
                      "group_decay": (p.group_decay, p.n_groups, "int64_t"),
                      "group_secular": (p.group_secular, p.n_groups, "int64_t"),
                      "group_end": (p.group_end, p.n_groups, "int64_t"),
                      "term_freq": (p.term_freq, n_terms, "int64_t"),
                      "term_coefficient": (p.term_coefficient, 6 * n_terms, "double")}
            for field, (pointer, n, kind_c) in arrays.items():
                values = [pointer[k] for k in range(n)]
                text = ", ".join(str(int(v)) if kind_c == "int64_t" else hexd(v) for v in values) or "0"
                lines.append(f"static const {kind_c} {name}_{field}[] = {{{text}}};")
            ints = lambda f: "{" + ", ".join(str(int(v)) for v in getattr(p, f)) + "}"  # noqa: E731
            dbls = lambda f: "{" + ", ".join(hexd(v) for v in getattr(p, f)) + "}"  # noqa: E731
            pieces.append(
                f"    {{{hexd(p.start)}, {p.n_decay_bases}, {p.n_freq_bases}, {dbls('decay_base')}, {dbls('freq_base')}, "
                f"{ints('decay_top')}, {ints('decay_bottom')}, {ints('decay_zero')}, {ints('freq_top')}, "
                f"{ints('freq_zero')}, {p.n_decay_table}, {p.n_decay_rows}, {p.n_freq_table}, {p.n_freq_rows}, "
                f"{name}_decay_chain, {name}_freq_chain, {p.n_groups}, {name}_group_decay, {name}_group_secular, "
                f"{name}_group_end, {name}_term_freq, {name}_term_coefficient}},")
        lines += [f"static const OePiece REF{kind}_PIECES[] = {{", *pieces, "};", ""]
        values = {"reference": float(kind), "x_ref_start": settings.x_start, "v_ref_start": settings.v_start,
                  **{n: float(getattr(ERRATA_SCENE, n)) for n in REFERENCE_DEPENDS[1:7]}}
        entries.append(f"    {{{kind}, {hexd(t0)}, {len(REFERENCE_DEPENDS)}, "
                       f"{{{', '.join('VR_' + n for n in REFERENCE_DEPENDS)}}}, "
                       f"{{{', '.join(hexd(values[n]) for n in REFERENCE_DEPENDS)}}}, {program.struct.n_pieces}, "
                       f"REF{kind}_PIECES, {_c_string(note)}}},")
    lines += [f"#define N_PACKED_REFERENCES {len(entries)}",
              "static const PackedReference PACKED_REFERENCES[N_PACKED_REFERENCES] = {", *entries, "};", "",
              "#endif", ""]
    return "\n".join(lines)


def _reason(check, *args) -> str:
    """The reason of the ParameterError that check(*args) raises."""
    from vibromodel.parameters import ParameterError

    try:
        check(*args)
    except ParameterError as error:
        return error.reason
    raise AssertionError(f"{check.__qualname__}{args} raised no ParameterError")


def model_sources(model_id: str, fmi_version: int = 2) -> list[Path]:
    """Every hand-written file of the model's native FMU (C sources and headers); FMI 3.0: the FMI 2.0 FMU's and
    the FMI 3.0 layer fmi3_native.c over it."""
    folder = NATIVE_SRC / model_id
    extra = [NATIVE_SRC / "fmi3_native.c"] if fmi_version == 3 else []
    return [*COMMON_SOURCES, *extra, *COMMON_HEADERS, folder / "native_model.c", folder / "config.h",
            *MODEL_FILES[model_id]]


def write_sources(model_id: str, model_description: bytes, out: Path, fmi_version: int = 2) -> list[str]:
    """All sources, flat, into out (with the generated headers); returns the C files to compile."""
    out.mkdir(parents=True, exist_ok=True)
    for path in model_sources(model_id, fmi_version):
        shutil.copyfile(path, out / path.name)
    (out / "variables.h").write_text(variables_header(with_derivative_variables(model_description)))
    (out / "rules.h").write_text(rules_header())
    (out / "rule_index.h").write_text(rule_index_header(with_derivative_variables(model_description)))
    (out / "state_fields.h").write_text(state_fields_header(model_id))  # what a restored state must obey
    if model_id == "HertzEAClosedLoop":
        (out / "reference.h").write_text(reference_header())
    return sorted(p.name for p in model_sources(model_id, fmi_version) if p.suffix == ".c")


def compile_binary(sources: Path, c_files: list[str], out: Path, target: str = "linux64") -> Path:
    """Compile the sources into out (linux64: gcc .so; win64: mingw .dll); RuntimeError with the compiler's
    output on failure."""
    command = (*toolchain.c_compiler(), *LINUX_COMMAND[1:]) if target == "linux64" else WIN64_COMMAND
    exports = []
    if "fmi3_native.c" in c_files and target == "linux64":  # the FMI 3.0 binary exports fmi3* only (fmi3_native.c)
        script = out.with_suffix(".map")
        script.write_text("{ global: fmi3*; local: *; };\n")
        exports = [f"-Wl,--version-script={script}"]
    cmd = [*command, f"-I{sources}", toolchain.fmi_include(), "-o", str(out), *(str(sources / f) for f in c_files),
           *exports, "-lm"]
    proc = compilers.run(cmd)  # (killed at once when a parallel build stops: fmus.compilers)
    if proc.returncode != 0 or proc.stderr.strip():
        raise RuntimeError(f"compiling {out.name} failed or warned ({' '.join(cmd)}):\n{proc.stderr}")
    return out


def win64_available() -> bool:
    return shutil.which(toolchain.WIN64_COMPILER) is not None


def native_model_description(model_description: bytes, c_files: list[str], fmi_version: int = 2) -> bytes:
    """The pythonfmu FMU's modelDescription.xml with the native FMU's capabilities and its source files (FMI 3.0:
    fmi3_model_description of that)."""
    if fmi_version == 3:
        return fmi3_model_description(native_model_description(model_description, c_files), c_files)
    root = ET.fromstring(model_description)
    root.set("generationTool", "vibrofmu native (interface of the pythonfmu FMU, C layer fmu_src/native)")
    cs = root.find("CoSimulation")
    model_id = cs.get("modelIdentifier")
    if model_id in ME_STATES:
        _add_model_exchange(root, cs, model_id, c_files)
    cs.set("needsExecutionTool", "false")
    cs.set("canBeInstantiatedOnlyOncePerProcess", "false")
    cs.set("canGetAndSetFMUstate", "true")
    cs.set("canSerializeFMUstate", "true")
    cs.set("canNotUseMemoryManagementFunctions", "true")
    if model_id in DIRECTIONAL_DERIVATIVES:
        cs.set("providesDirectionalDerivative", "true")
    for old in cs.findall("SourceFiles"):
        cs.remove(old)
    files = ET.SubElement(cs, "SourceFiles")
    for name in c_files:
        ET.SubElement(files, "File", name=name)
    for sv in root.iter("ScalarVariable"):
        if sv.get("name") == "fmi_status":
            sv.set("description", "0 ok, 3 error (the FMU's error flag)")
    ET.indent(root, "\t")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


def _add_model_exchange(root, cs, model_id: str, c_files: list[str]) -> None:
    """FMI 2.0 Model Exchange beside the co-simulation: <ModelExchange>, numberOfEventIndicators, each state's
    derivative variable (derivative= the state's index), <Derivatives> and <InitialUnknowns> in ModelStructure."""
    states, derivatives = ME_STATES[model_id]
    me = ET.Element("ModelExchange", modelIdentifier=model_id, needsExecutionTool="false",
                    completedIntegratorStepNotNeeded="true", canBeInstantiatedOnlyOncePerProcess="false",
                    canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate="true",
                    canSerializeFMUstate="true",
                    providesDirectionalDerivative=str(model_id in DIRECTIONAL_DERIVATIVES).lower())
    files = ET.SubElement(me, "SourceFiles")
    for name in c_files:
        ET.SubElement(files, "File", name=name)
    root.insert(list(root).index(cs), me)
    root.set("numberOfEventIndicators", str(len(ME_INDICATORS[model_id])))
    variables = list(root.find("ModelVariables"))
    index = {sv.get("name"): i + 1 for i, sv in enumerate(variables)}
    for state, derivative in zip(states, derivatives):
        real = variables[index[derivative] - 1].find("Real")
        real.set("derivative", str(index[state]))
    structure = root.find("ModelStructure")
    outputs = structure.find("Outputs")
    position = list(structure).index(outputs) + 1 if outputs is not None else 0
    block = ET.Element("Derivatives")
    for derivative in derivatives:
        ET.SubElement(block, "Unknown", index=str(index[derivative]))
    structure.insert(position, block)
    calculated = [d for d in derivatives if variables[index[d] - 1].get("initial") is None]  # the der(...) added
    if calculated:
        block = ET.Element("InitialUnknowns")
        for derivative in sorted(calculated, key=index.get):
            ET.SubElement(block, "Unknown", index=str(index[derivative]))
        structure.insert(position + 1, block)


# FMI 3.0's platform tuples of the folders under binaries/ (FMI 2.0: linux64, win64)
FMI3_PLATFORMS = ("x86_64-linux", "x86_64-windows")
_FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}


def fmi3_model_description(model_description: bytes, c_files: list[str]) -> bytes:
    """The FMI 3.0 modelDescription.xml of a native FMU from its FMI 2.0 one: the same variables and value
    references (Real -> Float64, Integer -> Int32), the independent variable `time` (value reference N), the event
    indicators as local variables (N + 1 ...) for the Model Exchange models, Co-Simulation with event mode and early
    return (the models with contact events), Model Exchange where the FMI 2.0 FMU has it."""
    old = ET.fromstring(model_description)
    cs2 = old.find("CoSimulation")
    model_id = cs2.get("modelIdentifier")
    has_me = old.find("ModelExchange") is not None
    root = ET.Element("fmiModelDescription", fmiVersion="3.0", modelName=old.get("modelName"),
                      instantiationToken=old.get("guid"), description=old.get("description", ""),
                      author=old.get("author", ""), generationTool=old.get("generationTool", ""),
                      generationDateAndTime=old.get("generationDateAndTime", ""),
                      variableNamingConvention=old.get("variableNamingConvention", "flat"))
    common = {"modelIdentifier": model_id, "needsExecutionTool": "false",
              "canBeInstantiatedOnlyOncePerProcess": "false", "canGetAndSetFMUState": "true",
              "canSerializeFMUState": "true",
              "providesDirectionalDerivatives": str(model_id in DIRECTIONAL_DERIVATIVES).lower()}
    if has_me:
        ET.SubElement(root, "ModelExchange", **common, needsCompletedIntegratorStep="false")
    early = "true" if model_id in EARLY_RETURN else "false"  # model_do_step_early
    ET.SubElement(root, "CoSimulation", **common, canHandleVariableCommunicationStepSize="true",
                  hasEventMode="true", mightReturnEarlyFromDoStep=early, canReturnEarlyAfterIntermediateUpdate="false",
                  providesIntermediateUpdate="false")
    for tag in ("UnitDefinitions", "LogCategories", "DefaultExperiment"):
        element = old.find(tag)
        if element is not None:
            root.append(element)
    variables = ET.SubElement(root, "ModelVariables")
    svs = list(old.find("ModelVariables"))
    n = len(svs)
    ET.SubElement(variables, "Float64", name="time", valueReference=str(n), causality="independent",
                  variability="continuous", description="simulation time tau")
    by_index = {i + 1: sv for i, sv in enumerate(svs)}
    for sv in svs:
        kind = next(child for child in sv if child.tag in _FMI3_TYPES)
        attributes = {"name": sv.get("name"), "valueReference": sv.get("valueReference")}
        for key in ("description", "causality", "variability", "initial"):
            if sv.get(key) is not None:
                attributes[key] = sv.get(key)
        for key in ("start", "unit"):
            if kind.get(key) is not None:
                attributes[key] = kind.get(key)
        if kind.get("derivative") is not None:
            attributes["derivative"] = by_index[int(kind.get("derivative"))].get("valueReference")
        ET.SubElement(variables, _FMI3_TYPES[kind.tag], **attributes)
    indicators = ME_INDICATORS.get(model_id, ()) if has_me else ()
    for k, (name, description) in enumerate(indicators):
        ET.SubElement(variables, "Float64", name=name, valueReference=str(n + 1 + k), causality="local",
                      variability="continuous", description=description)
    structure = ET.SubElement(root, "ModelStructure")
    for sv in svs:
        if sv.get("causality") == "output":
            ET.SubElement(structure, "Output", valueReference=sv.get("valueReference"))
    if has_me:
        names = {sv.get("name"): sv.get("valueReference") for sv in svs}
        for derivative in ME_STATES[model_id][1]:
            ET.SubElement(structure, "ContinuousStateDerivative", valueReference=names[derivative])
        initial = {sv.get("name"): sv.get("initial") for sv in svs}
        for derivative in ME_STATES[model_id][1]:
            if initial[derivative] is None:  # the der(...) added: calculated at initialisation
                ET.SubElement(structure, "InitialUnknown", valueReference=names[derivative])
        for k in range(len(indicators)):
            ET.SubElement(structure, "EventIndicator", valueReference=str(n + 1 + k))
    ET.indent(root, "\t")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


def build_description(model_id: str, c_files: list[str]) -> str:
    files = "".join(f'      <SourceFile name="{name}"/>\n' for name in c_files)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration modelIdentifier="{model_id}">\n    <SourceFileSet language="C11">\n{files}'
            '    </SourceFileSet>\n  </BuildConfiguration>\n</fmiBuildDescription>\n')


def build_native(pythonfmu_fmu: Path, out_dir: Path, win64: bool | None = None, reference: bool = True,
                 fmi_version: int = 2) -> Path:
    """out_dir/<id>.fmu from the pythonfmu FMU's interface (see the module's text); win64 None: when mingw is
    installed. reference: pack the default experiment's result into documentation/ (FMI 2.0 only).
    fmi_version 3: the FMI 3.0 FMU (fmi3_native.c over the same sources; FMPy's fmi3 headers)."""
    check_fidelity_header()  # the registry's levels as the C runs them (a level it cannot compute is refused here)
    with zipfile.ZipFile(pythonfmu_fmu) as z:
        md = with_derivative_variables(z.read("modelDescription.xml"))
    model_id = ET.fromstring(md).find("CoSimulation").get("modelIdentifier")
    from vibrofmu.fmus.archive import normalize_entries, publish, staging
    from vibrofmu.fmus.refresult import pack_reference

    out_dir = Path(out_dir)
    with staging(out_dir) as tmp:  # assembled here, moved to its name when complete (archive.staging)
        fmu = tmp / f"{model_id}.fmu"
        sources = Path(tmp) / "sources"
        c_files = write_sources(model_id, md, sources, fmi_version)
        linux64, win64_dir = ("linux64", "win64") if fmi_version == 2 else FMI3_PLATFORMS
        binaries = {f"binaries/{linux64}/{model_id}.so": compile_binary(sources, c_files, Path(tmp) / "lib.so")}
        if win64 or (win64 is None and win64_available()):
            binaries[f"binaries/{win64_dir}/{model_id}.dll"] = compile_binary(sources, c_files, Path(tmp) / "lib.dll",
                                                                         "win64")
        (sources / "buildDescription.xml").write_text(build_description(model_id, c_files))
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", native_model_description(md, c_files, fmi_version))
            z.writestr("resources/", b"")  # empty: a host extracts it, and fmi2Instantiate checks it exists
            for name, path in binaries.items():
                z.write(path, name)
            for path in sorted(sources.iterdir()):
                z.write(path, f"sources/{path.name}")
        if reference and fmi_version == 2:
            with _FMPY:  # one simulation at a time in this process (FMPy keeps process-wide state)
                pack_reference(fmu)
        normalize_entries(fmu)  # entries 0644, regular files
        return publish(fmu, out_dir / fmu.name)


def series_probe_library(out_dir: Path):
    """series.c alone as a shared library (ctypes), for the test that holds it to vibromodel.forces."""
    import ctypes

    out = Path(out_dir) / "series.so"
    cmd = [*toolchain.c_compiler(), *(part for part in toolchain.NATIVE_LINUX64 if part != "-fvisibility=hidden"),
           "-o", str(out), str(NATIVE_SRC / "series.c"), "-lm"]  # symbols visible
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling series.c failed ({' '.join(cmd)}):\n{proc.stderr}")
    library = ctypes.CDLL(str(out))
    d = ctypes.c_double
    library.vibro_series.restype = None
    library.vibro_series.argtypes = [ctypes.c_int, d, d, d, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                                     ctypes.c_void_p]
    return library
