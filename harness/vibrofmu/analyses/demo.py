"""`vibrofmu demo`: simulate the plant FMU and compare on the paper's numerical example (Omega = 2)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vibromodel.parameters import Scene
from vibromodel.plant import Settings

from vibrofmu.analyses.simulate import simulate

TABLE_TAUS = (10.0, 25.0, 50.0, 100.0, 200.0)
DEMO_SETTINGS = Settings(fidelity=0, solver=0, rtol=1e-10)


def run_demo(out_dir: Path, fmu: Path) -> int:
    """Run `fmu` (the plant FMU) on the paper's example into out_dir and print the comparison table."""
    print(f"FMU {fmu}")
    run, summary, reference = simulate(fmu, Scene(), DEMO_SETTINGS, stop_time=200.0, output_interval=0.1,
                            out_dir=out_dir, compare=True)
    if not run.completed:
        print(f"error: {run.stop_reason}")
        return 1
    x_ref = reference(np.array(TABLE_TAUS))[0]
    print(f"\nPaper example (Omega = 2), exact Eq. 3, adaptive DOP853 rtol {DEMO_SETTINGS.rtol:g}, "
          f"output interval 0.1")
    print(f"{'tau':>6}  {'x (FMU)':>18}  {'x (reference)':>18}  {'|difference|':>12}")
    for tau, xr in zip(TABLE_TAUS, x_ref):
        x_fmu = run.outputs["x"][int(round(tau / 0.1))]
        print(f"{tau:6.0f}  {x_fmu:18.10e}  {xr:18.10e}  {abs(x_fmu - xr):12.2e}")
    e = summary["error"]
    print(f"\nmax |x_FMU - x_ref| on [0, 200] = {e['max_abs_error_x']:.2e} "
          f"(RMS {e['rms_error_x']:.2e}); FMU wall time {run.wall_time:.3f} s")
    print(f"results in {out_dir}/ (result.csv, summary.json, x.png)")
    return 0
