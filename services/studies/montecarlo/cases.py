"""The Monte-Carlo's random cases: one chunk is one random set, one law and one fault family, its
runs differing in initial state, operator, faults and true parameters.

* Sets: a random convex polygon (4–6 faces, 1–2.5 m from a centre) or a random union of two
  overlapping rectangles (non-convex: an L, a T or a cross), each with |ψ| ≤ π/2 rows.
* Operators: a face rush (full deflection towards a point 1 m beyond a random face of the set,
  k_p 20–60 N) or a wander (towards a random point inside, deflection 0.3–1).
* Initial states: at rest, uniform inside the set at least 0.15 m from every face.
* Families (what the faults are; `inside` says whether the safety guarantee covers the run —
  docs/safety.md §3 and §6):
  none · can (CAN delay 0–24 ms each way, frame loss 0–20 %) · kill (the controller killed at
  0.3–3.5 s) · hang (hung 2–100 ms at 0.3–3.5 s) · operator (link delay 0–500 ms, loss 0–80 %,
  a blackout of 0–2 s) · mismatch (true m1, m3, a each 0.5–1.5 × nominal, no fault) ·
  beyond (CAN delay 26–60 ms each way and 20–40 % loss: outside the envelope, not claimed).
  Under output feedback the CAN families keep the loss but no delay (the batched controller has
  no form of the judged state's prediction under delay: sampled.py's stated limit).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sharedctl.batched import BatchProblem, OperatorBatch
from sharedctl.scenario import parse

from .loop import NEVER, PERIOD, LoopFaults, Oracle

FAMILIES = ("none", "can", "kill", "hang", "operator", "mismatch", "beyond")
LAWS = ("ce", "nce", "of")
SET_KINDS = ("convex", "union")
DURATION = 5.0             # s of operator per run (then the robots whose controller is gone are followed to rest)
START_MARGIN = 0.15        # m from every face at the start
PSI_LIMIT = math.pi / 2


@dataclass(frozen=True)
class ChunkCase:
    """What the runs of one chunk share, and their per-robot draws."""

    family: str
    law: str
    set_kind: str
    regions: list                 # [(K, T)]
    problem: BatchProblem
    faults: LoopFaults
    true_theta: np.ndarray        # (3, N)
    inside: np.ndarray            # (N,) bool: the run lies inside the guarantee's envelope
    draws: dict                   # per-robot parameters for the maps and the counterexamples


def kind_of(index: int, families: tuple = FAMILIES) -> tuple[str, str, str]:
    """(family, law, set kind) of chunk `index`: every combination of `families` in turn."""
    f = families[index % len(families)]
    law = LAWS[(index // len(families)) % len(LAWS)]
    kind = SET_KINDS[(index // (len(families) * len(LAWS))) % len(SET_KINDS)]
    return f, law, kind


def random_regions(rng: np.random.Generator, kind: str) -> list:
    """A random planar set with |ψ| ≤ π/2: rows [k_x, k_y, 0] with T = −offset (K q + T ≤ 0 inside)."""
    psi = [([0.0, 0.0, 1.0], -PSI_LIMIT), ([0.0, 0.0, -1.0], -PSI_LIMIT)]
    if kind == "convex":
        m = int(rng.integers(4, 7))
        angles = 2 * math.pi * (np.arange(m) + rng.uniform(-0.2, 0.2, m)) / m + rng.uniform(0, 2 * math.pi)
        rows = [([math.cos(a), math.sin(a), 0.0], -float(rng.uniform(1.0, 2.5))) for a in angles] + psi
        return [_region(rows)]
    w1, h1 = rng.uniform(2.0, 4.0), rng.uniform(0.9, 1.5)
    w2, h2 = rng.uniform(0.9, 1.5), rng.uniform(2.0, 4.0)
    x2, y2 = rng.uniform(-w1 / 2 + w2 / 2, w1 / 2 - w2 / 2), rng.uniform(-h2 / 2 + h1 / 2, h2 / 2 - h1 / 2)
    return [_region(_box(0.0, 0.0, w1, h1) + psi), _region(_box(x2, y2, w2, h2) + psi)]


def _box(cx, cy, w, h):
    return [([1.0, 0.0, 0.0], -(cx + w / 2)), ([-1.0, 0.0, 0.0], cx - w / 2),
            ([0.0, 1.0, 0.0], -(cy + h / 2)), ([0.0, -1.0, 0.0], cy - h / 2)]


def _region(rows):
    return (np.array([r for r, _ in rows], float), np.array([t for _, t in rows], float))


def _inside_points(rng, regions, count: int, margin: float) -> np.ndarray:
    """`count` points (3, count), uniform over the set at least `margin` from its faces, ψ small."""
    out = []
    while sum(p.shape[1] for p in out) < count:
        q = np.vstack([rng.uniform(-3, 3, (2, 4 * count)), rng.uniform(-0.3, 0.3, (1, 4 * count))])
        out.append(q[:, Oracle(regions).margin(q) >= margin])
    return np.hstack(out)[:, :count]


def scenario_data(regions, q0, target, kp: float, law: str, deflection: float = 1.0,
                  brake_torque: float | None = None) -> dict:
    """The scenario mapping (sharedctl/scenario.py) of one run: `sharedctl sim`/`demo` replay it (a
    `brake_torque` other than the robot's own goes to `[robot_sim]`). The robot's true parameters are the
    controller's: a scenario cannot say they differ (the `mismatch` family's counterexamples cannot be
    replayed as they ran)."""
    data = {
        "name": "montecarlo", "duration": DURATION, "dt": 0.001, "controller": law,
        "robot": {"kind": "omni3"},
        "region": [{"K": [list(map(float, row)) for row in K], "T": list(map(float, T))} for K, T in regions],
        "initial": {"q": [float(x) for x in q0], "qdot": [0.0, 0.0, 0.0]},
        "desired": {"kind": "point", "at": [float(x) for x in target]},
        "human": {"kind": "adversarial", "kp": float(kp), "deflection": float(deflection)},
    }
    if brake_torque is not None:
        data["robot_sim"] = {"brake_torque": float(brake_torque)}
    return data


def build(index: int, runs: int, rng: np.random.Generator, families: tuple = FAMILIES) -> ChunkCase:
    family, law, kind = kind_of(index, families)
    regions = random_regions(rng, kind)
    q0 = _inside_points(rng, regions, runs, START_MARGIN)
    targets, kp, deflection = _operators(rng, regions, runs)
    loop, _, _ = parse(scenario_data(regions, q0[:, 0], targets[:, 0], kp[0], law)).closed_loop(law)
    operators = OperatorBatch.adversaries(np.tile(kp, (3, 1)), targets, deflection)
    problem = BatchProblem.replicate(loop, q0.T, np.zeros((runs, 3)), operators)
    faults, theta, inside, draws = _faults(rng, family, law, runs, loop.model.theta)
    draws.update(kp=kp, deflection=deflection, target=targets, q0=q0)
    return ChunkCase(family, law, kind, regions, problem, faults, theta, inside, draws)


def _operators(rng, regions, runs):
    """Face rushes (70 %) and wanders: (targets (3, N), k_p (N,), deflection (N,))."""
    rush = rng.random(runs) < 0.7
    kp = rng.uniform(20.0, 60.0, runs)
    inside = _inside_points(rng, regions, runs, 0.05)
    r = rng.integers(0, len(regions), runs)
    targets = inside.copy()
    for i in np.flatnonzero(rush):
        K, T = regions[r[i]]
        planar = [j for j in range(len(K)) if np.linalg.norm(K[j, :2]) > 0.5]
        j = planar[int(rng.integers(0, len(planar)))]
        n = K[j, :2] / np.linalg.norm(K[j, :2])
        p = inside[:2, i]
        foot = p - (float(K[j, :2] @ p) + T[j]) / float(np.linalg.norm(K[j, :2])) * n
        targets[:2, i] = foot + n + rng.uniform(-1.0, 1.0) * np.array([-n[1], n[0]])
        targets[2, i] = 0.0
    deflection = np.where(rush, 1.0, rng.uniform(0.3, 1.0, runs))
    return targets, kp, deflection


def _periods(seconds):
    return np.rint(np.asarray(seconds) / PERIOD).astype(np.int64)


def _faults(rng, family: str, law: str, runs: int, nominal: np.ndarray):
    faults = LoopFaults.none(runs)
    theta = np.repeat(nominal[:, None], runs, axis=1)
    inside = np.ones(runs, bool)
    draws: dict = {}
    of = law == "of"
    if family in ("can", "beyond"):
        lo, hi, loss = (0.0, 24.0, (0.0, 0.2)) if family == "can" else (26.0, 60.0, (0.2, 0.4))
        delay_ms = np.zeros(runs) if of else rng.uniform(lo, hi, runs)
        draws.update(can_delay_ms=delay_ms, can_loss=rng.uniform(*loss, runs))
        # each way: the feedback is the delay older (and up to a period more: the encoder's sample),
        # the command arrives the delay later
        feedback = _periods(delay_ms / 1000.0) + (0 if of else rng.integers(0, 2, runs))
        faults = faults.replace(feedback=feedback, transit=_periods(delay_ms / 1000.0),
                                torque_loss=draws["can_loss"])
        inside[:] = family == "can"
    elif family == "kill":
        at = rng.uniform(0.3, 3.5, runs)
        draws["fault_t"] = at
        faults = faults.replace(kill_at=_periods(at))
    elif family == "hang":
        at, length = rng.uniform(0.3, 3.5, runs), rng.integers(1, 51, runs)
        draws.update(fault_t=at, hang_ms=length * PERIOD * 1000.0)
        faults = faults.replace(hang_at=_periods(at), hang_periods=length)
    elif family == "operator":
        delay_ms, loss = rng.uniform(0.0, 500.0, runs), rng.uniform(0.0, 0.8, runs)
        start, length = rng.uniform(0.0, 3.0, runs), rng.uniform(0.0, 2.0, runs)
        draws.update(operator_delay_ms=delay_ms, operator_loss=loss, blackout_t=start, blackout_s=length)
        faults = faults.replace(operator_delay=_periods(delay_ms / 1000.0), operator_loss=loss,
                                blackout_at=_periods(start), blackout_periods=_periods(length))
    elif family == "mismatch":
        factor = rng.uniform(0.5, 1.5, (3, runs))
        theta = theta * factor
        draws["mismatch"] = factor
    return faults, theta, inside, draws


def fault_specs(case: ChunkCase, i: int) -> list[str]:
    """The `--fault` specs (services/faults/spec.py) that replay run i's faults in `sharedctl demo`."""
    d, f = case.draws, case.faults
    specs = []
    if "can_delay_ms" in d:
        if d["can_delay_ms"][i] > 0:
            specs.append(f"can.delay_ms={d['can_delay_ms'][i]:.1f}")
        specs.append(f"can.loss={d['can_loss'][i]:.3f}")
    if f.kill_at[i] < NEVER:
        specs.append(f"controller.kill_at={f.kill_at[i] * PERIOD:.3f}")
    if f.hang_at[i] < NEVER:
        specs.append(f"controller.stop_at={f.hang_at[i] * PERIOD:.3f},{f.hang_periods[i] * PERIOD:.3f}")
    if "operator_delay_ms" in d:
        specs += [f"operator.delay_ms={d['operator_delay_ms'][i]:.0f}", f"operator.loss={d['operator_loss'][i]:.2f}"]
        if d["blackout_s"][i] > 0:
            specs.append(f"operator.blackout={d['blackout_t'][i]:.2f},{d['blackout_s'][i]:.2f}")
    return specs
