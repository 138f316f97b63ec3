"""The Monte-Carlo's chunks (services/studies/montecarlo/work.py, cases.py): reproducible from the
seed and the chunk's index alone, every family's runs drawn as its docstring says, and the summary's
bound the Clopper–Pearson one."""
from __future__ import annotations

import numpy as np

from sharedctl.services.studies.montecarlo.bound import upper_95
from sharedctl.services.studies.montecarlo.cases import FAMILIES, build, kind_of
from sharedctl.services.studies.montecarlo.executor import Chunk, chunk_rng
from sharedctl.services.studies.montecarlo.loop import NEVER, PERIOD
from sharedctl.services.studies.montecarlo.work import run_chunk, summarize

SHORT = 0.4     # s of operator: the machinery, not the envelope


def test_a_chunk_is_its_seed_and_index_and_nothing_else():
    chunk = Chunk(index=2, first_run=6, runs=3, seed=11)
    first, again = run_chunk(chunk, SHORT), run_chunk(chunk, SHORT)
    assert first == again
    other = run_chunk(Chunk(index=2, first_run=6, runs=3, seed=12), SHORT)
    assert other["min_margin"] != first["min_margin"]
    assert first["family"] == "kill" and len(first["min_margin"]) == 3


def test_the_families_draw_the_faults_their_names_say():
    for index in range(len(FAMILIES)):
        family, law, _ = kind_of(index)
        case = build(index, 200, chunk_rng(Chunk(index, 0, 200, 5)))
        f = case.faults
        starts_inside = min(np.min(-(K @ case.problem.q0 + T[:, None]) / np.linalg.norm(K, axis=1)[:, None], axis=0)
                            for K, T in case.regions[:1]) if len(case.regions) == 1 else None
        if starts_inside is not None:
            assert np.all(starts_inside >= 0.15 - 1e-9)
        if family == "can":
            assert f.transit.max() * PERIOD <= 0.024 + 1e-9 and f.torque_loss.max() <= 0.2
            assert f.transit.max() > 0 and case.inside.all()
        elif family == "beyond":
            assert f.transit.min() * PERIOD >= 0.026 - PERIOD and not case.inside.any()
        elif family == "kill":
            assert np.all((f.kill_at * PERIOD >= 0.3 - PERIOD) & (f.kill_at * PERIOD <= 3.5 + PERIOD))
        elif family == "hang":
            assert f.hang_periods.min() >= 1 and f.hang_periods.max() <= 50
        else:
            assert np.all(f.kill_at == NEVER) and np.all(f.hang_at == NEVER) and not f.transit.any()
        if family == "mismatch":
            ratio = case.true_theta / case.problem.theta
            assert ratio.min() >= 0.5 and ratio.max() <= 1.5 and ratio.std() > 0.2


def test_the_summary_counts_runs_and_bounds_each_family_by_clopper_pearson():
    rows = [{"family": "kill", "runs": 4, "min_margin": [0.1, -0.01, 0.2, 0.05],
             "violated": [False, True, False, False],
             "inside": [True] * 4, "estopped": [False] * 4, "counterexamples": []},
            {"family": "beyond", "runs": 2, "min_margin": [-0.2, 0.3], "violated": [True, False],
             "inside": [False] * 2, "estopped": [True, False], "counterexamples": []}]
    s = summarize(rows, 2.0)
    assert (s["runs"], s["violations"], s["violations_inside_envelope"], s["min_margin"]) == (6, 2, 1, -0.2)
    assert s["runs_per_s"] == 3.0
    kill = next(f for f in s["families"] if f["family"] == "kill")
    assert kill["upper_95"] == upper_95(1, 4) and kill["violations"] == 1


def test_a_counterexample_is_drawn_again_from_its_chunk_as_a_scenario_the_processes_take():
    import tomllib

    from sharedctl.scenario import parse
    from sharedctl.services.studies.montecarlo.cases import fault_specs
    from sharedctl.services.studies.montecarlo.replay import rebuild
    from sharedctl.services.studies.montecarlo.report import scenario_toml

    runs, chunk_runs, seed = 20, 8, 4
    chunk = Chunk(index=1, first_run=8, runs=8, seed=seed)          # the second chunk: family "can"
    case = build(1, 8, chunk_rng(chunk))
    data, faults = rebuild(13, runs, seed, chunk_runs, FAMILIES)
    assert faults == fault_specs(case, 5) and any(f.startswith("can.loss=") for f in faults)
    assert data["initial"]["q"] == [float(x) for x in case.draws["q0"][:, 5]]
    assert data["human"]["deflection"] == float(case.draws["deflection"][5])
    loop, q0, _ = parse(tomllib.loads(scenario_toml(data, faults))).closed_loop()
    np.testing.assert_allclose(q0, case.draws["q0"][:, 5])
    assert loop.controller.name == case.law
