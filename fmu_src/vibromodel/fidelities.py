"""The fidelity registry: THE one place that lists the fidelity levels of the plant. One entry per level says
everything that depends on the level: its number (the enum Fidelity), command-line name, the FMU parameter's text,
its model and (open-loop levels) its solution's factory, what the compiled core and the native FMUs run of it,
and what the speed bench and ladder measure of it. Everything else reads the entries' properties, never level
numbers: plant.Plant, compiled.CompiledPlant, compiled_open_loop, compiled_loop, closedloop, settings, the FMU
slaves, the harness's simulate, bench and ladder, and the C (core/fidelity.h, generated from here by c_header()).

Adding a fidelity: a model (or solution) it evaluates, one entry here, and core/fidelity.h regenerated
(`python3 -m vibrofmu.fmus.kernel`); parameters.RULES's `fidelity` rule must equal rule() (tests/model/test_fidelity_registry.py
says when it does not: parameters cannot import this module, whose factories validate scenes with those rules).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Callable

from . import error_estimates
from .analytic import FIT_REFUSE, FIT_WARN, cached_solve, check_fit, covering
from .models import CModel, ExactModel, PolynomialModel, scene_model
from .parameters import ParameterError, Rule, Scene


class Fidelity(IntEnum):
    EXACT = 0
    POLYNOMIAL = 1
    POLYNOMIAL_PAPER = 2
    AVERAGED = 3  # slow flow (averaging.py, slowflow.py); its forces are those of Eq. 3 at x
    ANALYTIC = 4  # OAFM closed form (analytic.py); its forces are those of Eq. 3 at x~


AUTO = -1  # the `fidelity` value that asks for fidelity auto (auto.py): the plant FMU picks the level by `tolerance`


class Evaluator(IntEnum):
    """The compiled per-output evaluator of an open-loop level (core/openloop_plant.c)."""
    NONE = 0  # none: the level integrates (or runs in Python only)
    SLOWFLOW = 1  # core/slowflow_eval.c: the table of compiled_open_loop.slowflow_table
    OAFM = 2  # core/oafm_eval.c: the sums of compiled_open_loop.OafmProgram


@dataclass(frozen=True)
class FidelityEntry:
    """level: the FMU's `fidelity` value; key: its command-line name; description: the FMU parameter's text.
    model(scene): the forces (and x'' for an integrated level) of the level.
    integrated: the plant steps model.accel with DOP853 or RK4 (Eq. 3 or Eq. 7); such a level can be a closed
    loop's plant.
    c_model: the compiled core's model of the level's forces (models.CModel), None if the core has none (then the
    level runs in Python only, and the native FMUs must refuse it). It must be the c_model of the level's model
    objects: the compiled plants fill the core's model from the model object (compiled_fields()), so they compute
    what the Python plant does; the native FMUs fill it from their parameters (native/plant_setup.c), so they run
    the level only if its model is the scene's own model of that kind (native_mismatch), else c_header() refuses
    the level unless native_refusal says why the native FMUs cannot run it.
    open_loop(scene, settings, t0, stop_time, cache_dirs) -> (solution, notes): for a level whose doStep evaluates a
    precomputed solution (solution.state(t) -> (x, x', x'')) with U = 0; None for integrated levels.
    evaluator: the compiled per-output evaluator of an open-loop level (Evaluator.NONE: none, Python evaluates).
    solution_in_snapshot: the solution holds state that FMU states must carry (it grows as the run advances).
    check_settings(settings): raises ParameterError for settings only this level has (None: none).
    work(solution) -> dict: what the set-up of an open-loop level did (table size, fit size...), for the bench.
    uses_rtol: the level's result depends on Settings.rtol (every integrated level; fidelity 3's slow flow).
    native_refusal: None if the native FMUs (fmu_src/native) run the level, else why they cannot (their fmi2Error
    says it, then "(fidelity N needs Python)" and the pythonfmu FMU to use instead).
    below_target: the level's own model error exceeds the bench's accuracy target (speed/bench.py THRESHOLD), so
    the bench does not search the target's settings for it.
    ladder: the level is a rung of the speed ladder (speed/ladder.py; the first such level is its base);
    ladder_limit: the rung's acceptance limit there, cost per output over the base's (None: none).
    error_estimate(scene, settings, model, solution, span) -> {"estimate", "amplitude", "terms"}: the level's estimate
    of max|x - x_exact| over a run of span (vibromodel/error_estimates.py); warn_share: above this share of the
    amplitude the plant warns (fmi2Warning) with the estimate (None: never; the integrated levels); refuse_share:
    above this share, or when it cannot estimate, the plant refuses the scene (ParameterError naming `fidelity`)."""

    level: Fidelity
    key: str
    description: str
    model: Callable[[Scene], object]
    integrated: bool
    c_model: CModel | None
    open_loop: Callable | None = None
    evaluator: Evaluator = Evaluator.NONE
    solution_in_snapshot: bool = False
    check_settings: Callable | None = None
    work: Callable | None = None
    uses_rtol: bool = True
    native_refusal: str | None = None
    below_target: bool = False
    ladder: bool = False
    ladder_limit: float | None = None
    error_estimate: Callable | None = None
    warn_share: float | None = None
    refuse_share: float | None = None

    @property
    def name(self) -> str:
        """The description without its leading level number ("averaged slow flow")."""
        return self.description.split(" ", 1)[1]

    @property
    def oafm_settings(self) -> bool:
        """The level reads the OAFM settings (analytic.OafmSettings, checked by its validate())."""
        return self.check_settings is _check_oafm

    @property
    def rung(self) -> str:
        """The level's name on the speed ladder ("averaged f3")."""
        return f"{self.key} f{int(self.level)}"


def _averaged_solution(scene, settings, t0, stop_time, cache_dirs):
    """Fidelity 3: the averaged slow flow integrated with large steps (docs/model.md, Averaging and slow flow)."""
    from .averaging import checked_averaged, validity_estimates, validity_notes  # only fidelity 3 loads them
    from .slowflow import SlowFlowSolution

    model = checked_averaged(scene)  # ParameterError without a stable equilibrium (static pull-in)
    refusal, warnings = validity_estimates(model)  # the averaging's own domain, before any integration
    if refusal is not None:
        raise refusal
    # a window of the table at a time (slowflow.WINDOW); tabulated on the compiled kernel where the settings ask for it
    # (settings.Kernel.COMPILED = 0, its first value) and one is loaded (slowflow_kernel)
    solution = SlowFlowSolution(model, t0, scene.x_start, scene.v_start, settings.rtol, settings.max_step or math.inf,
                                stop_time, bounded=True, kernel=settings.kernel == 0)
    notes = [f"averaged slow flow (docs/model.md, Averaging and slow flow, {model.backbone.kind} backbone): x_e = {model.eq.x_e:.6g}, omega_e = "
             f"{model.omega_e:.8g}, table spacing {solution.spacing:.3g}"]
    solution.warnings = warnings + solution.amplitude_warnings
    return solution, notes + [f"outside the averaging's validity: {note}" for note in validity_notes(model)]


def _analytic_solution(scene, settings, t0, stop_time, cache_dirs):
    """Fidelity 4: the OAFM solution fitted to cover [t0, stop_time] (or read from a cache)."""
    span = None if stop_time is None else stop_time - t0
    oafm = covering(scene, settings.oafm, span, strict=True)  # refuses a fit beyond analytic.MAX_FIT_SPAN
    solution, source = cached_solve(scene, oafm, t0, read_dirs=cache_dirs)  # refuses outside the linear domain
    solution.warnings = check_fit(scene, solution, t0)  # refuses outside the domain; the error estimate's warning
    notes = [f"OAFM {oafm.basis} basis, tau* = {solution.pieces[1].start:.6g}, fit to tau = {solution.tau_end:.6g} "
             f"({source})"]
    if stop_time is None:
        notes.append(f"no stop time given: beyond tau = {solution.tau_end:.6g} the analytic solution extrapolates "
                     "the fit")
    return solution, notes


def _averaged_work(solution) -> dict:
    return {"slow_flow_integration_seconds": solution.integration_seconds, "table_cells": len(solution.cells),
            "table_spacing": solution.spacing}


def _analytic_work(solution) -> dict:
    return {"pieces": len(solution.pieces), "convergence_control_parameters": sum(len(c) for c in solution.C)}


def _check_oafm(settings) -> None:
    settings.oafm.validate()


NATIVE_NEEDS_PYTHON = "needs Python"  # native_refusal's words before "; use the pythonfmu FMU ..."

REGISTRY: dict[Fidelity, FidelityEntry] = {e.level: e for e in (
    FidelityEntry(Fidelity.EXACT, "exact", "0 exact Eq. 3", ExactModel, True, CModel.EXACT, ladder=True,
                  error_estimate=error_estimates.exact_estimate),
    FidelityEntry(Fidelity.POLYNOMIAL, "polynomial", "1 polynomial Eq. 7", PolynomialModel, True, CModel.POLYNOMIAL,
                  ladder=True, error_estimate=error_estimates.polynomial_estimate),
    FidelityEntry(Fidelity.POLYNOMIAL_PAPER, "polynomial-paper", "2 Eq. 7 printed coefficients",
                  lambda scene: PolynomialModel(scene, printed=True), True, CModel.POLYNOMIAL_PRINTED,
                  below_target=True,  # its model error (~2e-8, the printed coefficients) is above the target's 1e-8
                  error_estimate=error_estimates.polynomial_estimate),
    FidelityEntry(Fidelity.AVERAGED, "averaged", "3 averaged slow flow", ExactModel, False, CModel.EXACT,
                  open_loop=_averaged_solution, evaluator=Evaluator.SLOWFLOW, solution_in_snapshot=True,
                  work=_averaged_work, native_refusal="the native FMU cannot tabulate the averaged slow flow",
                  ladder=True, ladder_limit=0.5, error_estimate=error_estimates.averaged_plant_estimate,
                  warn_share=error_estimates.AVERAGED_WARN_SHARE),
    FidelityEntry(Fidelity.ANALYTIC, "analytic", "4 OAFM analytic", ExactModel, False, CModel.EXACT,
                  open_loop=_analytic_solution, evaluator=Evaluator.OAFM, check_settings=_check_oafm,
                  work=_analytic_work, uses_rtol=False, native_refusal="the native FMU cannot fit the OAFM solution",
                  ladder=True, ladder_limit=0.5, error_estimate=error_estimates.analytic_plant_estimate,
                  warn_share=FIT_WARN, refuse_share=FIT_REFUSE),
)}


def entry(fidelity: int) -> FidelityEntry:
    """The registry's entry of a fidelity level; ParameterError for an unknown one."""
    try:
        return REGISTRY[Fidelity(fidelity)]
    except ValueError:
        raise ParameterError("fidelity", fidelity, f"must be one of {[int(f) for f in REGISTRY]}") from None


def make_model(scene: Scene, fidelity: int):
    """The plant model of a fidelity level: 0, 1, 2 step it; 3 and 4 use Eq. 3's forces at their x."""
    return entry(fidelity).model(scene)


def keys() -> dict[str, int]:
    """Command-line names -> levels."""
    return {e.key: int(e.level) for e in REGISTRY.values()}


def open_loop() -> tuple[Fidelity, ...]:
    """The levels whose doStep evaluates a precomputed solution (approximations of Eq. 3 no setting refines)."""
    return tuple(e.level for e in REGISTRY.values() if not e.integrated)


def integrated() -> tuple[Fidelity, ...]:
    """The levels whose plant steps Eq. 3 or 7 (the closed loop's possible plants)."""
    return tuple(e.level for e in REGISTRY.values() if e.integrated)


def _spoken(levels) -> str:
    """"0, 1 or 2"."""
    words = [str(int(level)) for level in levels]
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} or {words[-1]}"


def description(levels=None) -> str:
    """The FMU `fidelity` parameter's text: "0 exact Eq. 3, 1 polynomial Eq. 7, ..." for `levels` (default all)."""
    return ", ".join(entry(level).description for level in (REGISTRY if levels is None else levels))


def closed_loop_refusal() -> str:
    """Why a closed loop refuses a level that does not integrate (closedloop.ClosedLoop, the native closed loop)."""
    return f"the closed loop's plant must be {_spoken(integrated())}"


def native_refusal(level: int) -> str | None:
    """The native FMUs' text for a level they cannot run ("... (fidelity 3 needs Python)"), None if they run it."""
    why = entry(level).native_refusal
    return None if why is None else f"{why} (fidelity {int(level)} {NATIVE_NEEDS_PYTHON})"


def rule() -> Rule:
    """parameters.RULES's `fidelity` rule: a whole number from the lowest to the highest level or AUTO, the reason
    naming the levels by kind ("0 exact, 1 and 2 polynomial, 3 averaged, 4 analytic": levels of one model kind share
    their name) and auto. Only the plant accepts AUTO: the closed loop refuses it (closed_loop_refusal)."""
    groups: dict[str, list[int]] = {}
    for e in REGISTRY.values():
        groups.setdefault(e.key.split("-")[0], []).append(int(e.level))
    reason = ", ".join(f"{' and '.join(map(str, levels))} {kind}" for kind, levels in groups.items())
    return Rule("fidelity", int(min(REGISTRY)), int(max(REGISTRY)), reason=f"{reason}, {AUTO} auto", integer=True,
                automatic=AUTO)


def open_loop_rule_levels() -> tuple[int, ...]:
    """The levels parameters.RULES's rules of the open-loop levels apply to (`when` of omega's and Omega's
    MIN_AVERAGED_FREQUENCY rules): each is built per forcing period."""
    return tuple(int(level) for level in open_loop())


# What c_header() says when the native FMUs cannot compute a level's model
NATIVE_CANNOT = ("the native FMUs compute the compiled model from the FMU's parameters alone (native/plant_setup.c), "
                 "so they cannot run this level: give its registry entry a native_refusal (they then refuse it) or a "
                 "c_model whose native set-up computes it")


def probe_scenes() -> dict[str, Scene]:
    """The scenes native_mismatch compares on, by name: the paper scene, every parameter moved off it, the forcing
    off."""
    paper = Scene()
    return {"the paper scene": paper,
            "the paper scene with every parameter moved": paper.with_values(
                mu=0.137, Delta=0.0011, omega=1.3, Omega=1.7, alpha=0.0023, beta=0.00031, gamma=0.00047, R=1.9,
                x_start=0.03, v_start=0.01),
            "the paper scene without forcing": paper.with_values(Delta=0.0, alpha=0.0, beta=0.0, gamma=0.0)}


def compiled_kind_mismatch(e: FidelityEntry) -> str | None:
    """None if the level's model object is of the entry's compiled kind (its c_model), else what it is."""
    model = e.model(Scene())
    kind = getattr(model, "c_model", None)
    if kind != e.c_model:
        return (f"its model {type(model).__name__} has compiled model {getattr(kind, 'name', kind)}, the entry says "
                f"{e.c_model.name}")
    return None


def native_mismatch(e: FidelityEntry) -> str | None:
    """None if the level's model object is, on every probe scene, the scene's own model of its compiled kind (the
    same VkModel fields to the bit: what the native FMUs compute from their parameters), else the first difference."""
    for where, scene in probe_scenes().items():
        ours, native = e.model(scene).compiled_fields(), scene_model(scene, e.c_model).compiled_fields()
        for name, value in ours.items():
            if repr(value) != repr(native[name]):
                return (f"its model's {name} is {value!r} on {where}, where the native FMUs' set-up from the "
                        f"parameters (the scene's {e.c_model.name} model) gives {native[name]!r}")
    return None


def c_header() -> str:
    """core/fidelity.h: the registry for the C of fmu_src/core and fmu_src/native (they branch on these properties,
    never on level numbers). Committed; tests/model/test_fidelity_registry.py checks that it is current."""
    rows = []
    for e in REGISTRY.values():
        refusal = native_refusal(e.level)
        rows.append(f"    {{{int(e.integrated)}, {-1 if e.c_model is None else int(e.c_model)}, {int(e.evaluator)}, "
                    f"{int(e.oafm_settings)}, {'NULL' if refusal is None else _c_string(refusal)}}},"
                    f"  /* {int(e.level)} {e.key} */")
        if e.c_model is None and refusal is None:
            raise ValueError(f"fidelity {int(e.level)} has no compiled model: the native FMUs must refuse it")
        problem = None if e.c_model is None else compiled_kind_mismatch(e)
        if problem is not None:
            raise ValueError(f"fidelity {int(e.level)} ({e.key}): {problem}")
        problem = None if e.c_model is None or refusal is not None else native_mismatch(e)
        if problem is not None:
            raise ValueError(f"fidelity {int(e.level)} ({e.key}): {problem}: {NATIVE_CANNOT}")
    if list(REGISTRY) != list(range(len(REGISTRY))):
        raise ValueError("the C indexes VK_FIDELITIES by level: levels must run 0..N-1")
    lines = ["/* fidelity.h -- the fidelity registry (vibromodel/fidelities.py) for the C of fmu_src/core and",
             " * fmu_src/native: they branch on these properties of a level, never on its number.  Generated by",
             " * vibromodel.fidelities.c_header() (python3 -m vibrofmu.fmus.kernel); do not edit. */",
             "#ifndef VIBRO_FIDELITY_H", "#define VIBRO_FIDELITY_H", "", "#include <stddef.h>", ""]
    lines += [f"#define VK_FID_{e.level.name} {int(e.level)}" for e in REGISTRY.values()]
    lines += [f"#define VK_N_FIDELITIES {len(REGISTRY)}", "",
              "/* the compiled core's model of a level's forces (fidelities.CModel): VkModel.polynomial = model > 0 */",
              "#define VK_MODEL_NONE (-1)"]
    lines += [f"#define VK_MODEL_{kind.name} {int(kind)}" for kind in CModel]
    lines += ["", "/* an open-loop level's per-output evaluator (fidelities.Evaluator) */"]
    lines += [f"#define VK_EVALUATOR_{kind.name} {int(kind)}" for kind in Evaluator]
    lines += ["", "typedef struct {",
              "    int integrated;              /* the plant steps Eq. 3 or 7 (a closed loop's possible plant) */",
              "    int model;                   /* VK_MODEL_*: the level's forces (and x'' when integrated) */",
              "    int evaluator;               /* VK_EVALUATOR_*: an open-loop level's evaluator */",
              "    int oafm_settings;           /* the level reads the OAFM settings (OafmSettings.validate) */",
              "    const char *native_refusal;  /* NULL: the native FMUs run it; else their refusal */",
              "} VkFidelity;", "",
              "static const VkFidelity VK_FIDELITIES[VK_N_FIDELITIES] = {", *rows, "};", "",
              f"#define VK_FIDELITY_CLOSED_LOOP_REFUSAL {_c_string(closed_loop_refusal())}", "", "#endif", ""]
    return "\n".join(lines)


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'
