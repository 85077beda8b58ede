"""The FMI conformance campaign (issue 25): every resource-location form, GUID and interface check, the NULL state
arguments and N forged states (plus, for the native FMUs, the sweep of every state word) over built FMUs, each
FMU and scenario in a subprocess of the probe host (vibrofmu.hosts.probe), so a crash or a hang is counted.

    python -m vibrofmu.analyses.conformance [N [SEED]] [FMU ...]

N forged states per FMU (default 5,000: 15,000 per FMU kind over the three FMUs of build/ and build/native/), SEED
their seed (default 2500). Prints one line per FMU and scenario and the totals; exits 1 on any crash, hang,
fmi2Fatal or wrong answer.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from vibrofmu.hosts.forge import summary
from vibrofmu.hosts.probe import run_probe

TIMEOUT = 1800.0  # s per FMU and scenario: a hang is counted, not waited for


def probe(scenario: str, fmu: Path, *args: str) -> tuple[str, list[dict]]:
    """('ok' | 'crash (signal or exit code)' | 'hang', the JSON lines)."""
    try:
        code, lines, _ = run_probe(scenario, fmu, *args, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return "hang", []
    return ("ok" if code == 0 else f"crash (exit {code})"), lines


def campaign(fmus: list[Path], n: int, seed: int) -> dict:
    totals = {"crashes": 0, "hangs": 0, "wrong": 0, "forged": 0, "refused": 0, "fatal": 0}
    for fmu in fmus:
        native = fmu.parent.name == "native"
        runs = [("instantiate",), ("states",), ("forged", str(n), str(seed))] + ([("forged", "0", "0", "sweep")]
                                                                                 if native else [])
        for scenario, *args in runs:
            outcome, lines = probe(scenario, fmu, *args)
            totals["crashes"] += outcome.startswith("crash")
            totals["hangs"] += outcome == "hang"
            detail = ""
            if scenario == "instantiate":
                wrong = [line["case"] for line in lines if line["accepted"] != line["expected"]]
                totals["wrong"] += len(wrong)
                detail = f"{len(lines)} cases, wrong: {wrong or 'none'}"
            elif scenario == "states":
                detail = f"{len(lines)} calls"
            elif (counts := summary(lines)) is not None:
                totals["forged"] += sum(counts.values())
                totals["refused"] += counts["refused"]
                totals["fatal"] += counts["fatal"]
                detail = f"{counts}" + (" (sweep)" if args[-1] == "sweep" else "")
            print(f"{'native' if native else 'pythonfmu':9s} {fmu.stem:27s} {scenario:11s} {outcome}: {detail}",
                  flush=True)
    return totals


def main(argv: list[str]) -> int:
    numbers = [a for a in argv if a.isdigit()]
    n = int(numbers[0]) if numbers else 5000
    seed = int(numbers[1]) if len(numbers) > 1 else 2500
    fmus = [Path(a) for a in argv if not a.isdigit()]
    if not fmus:
        fmus = sorted(Path("build").glob("*.fmu")) + sorted(Path("build/native").glob("*.fmu"))
    if not fmus:
        print("error: no FMU given and none in build/ (run 'vibrofmu build')", file=sys.stderr)
        return 2
    totals = campaign(fmus, n, seed)
    print(f"totals: {totals}")
    return 1 if totals["crashes"] or totals["hangs"] or totals["wrong"] or totals["fatal"] else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
