"""`vibrofmu bench --peers` (vibrofmu.speed.peers): the peers integrate the plant's model, the cheapest setting and
the verdicts are picked as documented, and the report block shows them. Speed itself is never asserted here."""
import json
import math

import numpy as np

from vibrofmu import report
from vibrofmu.speed import peers
from vibromodel.fidelities import Fidelity, make_model
from vibromodel.parameters import Scene


def test_the_peers_right_hand_side_is_the_exact_model():
    """peers.accel against models.ExactModel.accel on random states of both scenes and a scene with every term:
    the same formula in another order of terms, so equal to within a few roundings of the largest term (4 ulp of
    the terms' magnitude, here ~1 + |alpha F2|)."""
    rng = np.random.default_rng(35)
    for scene in (*peers.SCENES.values(), Scene(alpha=0.05, beta=0.01, gamma=0.002, R=1.5, Delta=0.3)):
        model, p = make_model(scene, Fidelity.EXACT), peers.parameters(scene)
        for t, x, v in zip(rng.uniform(0, 200, 200), rng.uniform(-1.45 * scene.R, 1.4 * scene.R, 200),
                           rng.uniform(-2, 2, 200)):
            expected = model.accel(t, x, v, 0.0)
            scale = 1.0 + abs(x) + abs(v) + abs(expected)
            assert abs(peers.accel(t, x, v, p) - expected) <= 4 * np.spacing(scale), (scene, t, x, v)


def test_the_contact_loss_scene_loses_contact():
    """The second scene must open the contact (1 + 2x/3 <= 0) and close it again, or it tests no kink."""
    from vibrofmu.analyses.reference import reference_solution

    reference = reference_solution(peers.SCENES["contact loss"], 0, 50.0)
    assert len(reference.contact_changes) >= 2


def table(*rows):
    """{rtol: entry} from (rtol, error, seconds per round)."""
    return {rtol: {"error": error, "rounds": list(rounds), "seconds": min(rounds)} for rtol, error, rounds in rows}


def test_cheapest_is_the_fastest_setting_within_the_error():
    t = table((1e-4, 3e-6, (1.0, 1.1)), (1e-6, 5e-7, (2.0, 1.5)), (1e-8, 2e-9, (1.2, 1.4)), (1e-10, None, (0.1, 0.1)))
    assert peers.cheapest(t, 1e-6) == (1e-8, t[1e-8])  # 1e-8 is within and cheaper than 1e-6; the failed run is out
    assert peers.cheapest(t, 1e-9) is None


def test_verdicts_compare_ours_with_the_best_peer_per_round():
    results = {"paper": {
        "native FMU, C host": table((1e-7, 1e-7, (2.0, 3.0, 2.5))),
        "Python API": table((1e-7, 1e-7, (4.0, 4.0, 5.0))),
        "numbalsoda LSODA": table((1e-7, 2e-7, (3.0, 2.0, 4.0)), (1e-5, 2e-6, (0.5, 0.5, 0.5))),
        "CVODE Adams": table((1e-7, 9e-7, (6.0, 6.0, 6.0))),
    }}
    rows = {row["threshold"]: row for row in peers.verdicts(results)}
    row = rows[1e-6]
    assert row["best_peer"] == "numbalsoda LSODA"  # its 1e-5 setting misses 1e-6; its 1e-7 one (min 2.0) wins
    assert row["native FMU, C host"]["over_best_peer"] == 1.0
    assert row["native FMU, C host"]["per_round"] == [2.0 / 3.0, 1.5, 2.5 / 4.0]
    assert row["Python API"]["over_best_peer"] == 2.0
    assert rows[1e-9]["best_peer"] is None and "Python API" not in rows[1e-9]
    lines = peers.peers_lines({"verdicts": [row], "missing": {"diffrax": "no module jax"}})
    assert lines[0] == "peers missing: diffrax: no module jax"
    assert "native FMU, C host / best peer (numbalsoda LSODA): 1.00x (met: <= 1.0" in lines[2]
    assert "Python API / best peer (numbalsoda LSODA): 2.00x (NOT met" in lines[3]


def test_missing_peers_are_named_in_one_line_each():
    missing = peers.missing_peers()
    for peer, why in missing.items():
        assert peer in (*peers.PEER_PACKAGES, "CVODE") and why and "\n" not in why


def test_the_report_block_reads_peers_json(tmp_path):
    record = {"peers": {"command": "vibrofmu bench --peers --ladder-rounds 3"},
              "machine": {"started_utc": "2026-11-27 23:00 UTC", "cpu_count": 2, "load_average_at_start": [1.5]},
              "missing": {}, "one_off_seconds": {"numbalsoda": 2.5},
              "verdicts": [{"scene": "paper", "threshold": 1e-6, "best_peer": "CVODE Adams",
                            "contenders": {"CVODE Adams": {"rtol": 1e-7, "seconds": 0.0005, "error": 1e-7}},
                            "native FMU, C host": {"over_best_peer": 0.9, "per_round": [0.9, 0.95, 1.0]}}],
              "short_scenes": None}
    (tmp_path / "peers.json").write_text(json.dumps(record))
    body = report.summary_block("peers", [tmp_path])
    assert body.splitlines()[0].startswith("`vibrofmu bench --peers --ladder-rounds 3` (2026-11-27 23:00 UTC, 2 CPUs")
    assert "- paper scene, error <= 1e-06 (ms per run, cheapest rtol reaching it): CVODE Adams 0.5" in body
    assert "  - native FMU, C host / best peer (CVODE Adams): 0.90x (met" in body
    assert report.summary_block("peers", [tmp_path / "nothing"]) is None
    assert not math.isnan(record["verdicts"][0]["native FMU, C host"]["over_best_peer"])
