"""Builders and hypothesis strategies for the closed-loop safety and sharing tests.

Every random case is built from one integer seed by a numpy generator (rejection sampling
where a geometric assumption must hold), so a failing example is reproduced exactly by
`<builder>(seed)`; hypothesis chooses the seeds. The assumptions every generated set
satisfies are stated in tests/test_invariance_properties.py's docstring and checked here
by `check_band_assumptions`.

Builders are memoised (one Case object per argument) and runs are cached per (case,
controller, dt, sharing, duration), so the invariance and the sharing tests assert their
different properties on one simulation without paying for it twice.
"""
from __future__ import annotations

import functools
import itertools
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources

import numpy as np
from hypothesis import HealthCheck, Phase
from hypothesis import strategies as st
from scipy import integrate
from scipy.optimize import linprog

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.human import ArbitraryOperator, CircleTrajectory, LineTrajectory, ScriptedOperator
from sharedctl.scenario import parse
from sharedctl.sets import Bands, SetClass
from sharedctl.sharing import Authority, SharingParameters
from sharedctl.simulator import ClosedLoop, Trace, simulate

DT = 2e-3
BANDS = Bands()                       # b1 = 0.3, b2 = 0.6 (the defaults every case uses)
CONTROLLERS = ("ce", "nce", "of")
HALF_PI = math.pi / 2
PSI_K = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]   # ψ ≤ π/2 and −ψ ≤ π/2
PSI_T = [-HALF_PI, -HALF_PI]
KP, KD = 20.0, 12.0                   # the scripted operator of the paper scenarios


# ----- one case: everything but the controller ---------------------------------------------
@dataclass(eq=False)
class Case:
    """A closed loop without its machine controller: plant, set, operator, initial state."""

    label: str                         # how to rebuild it, e.g. "random_convex_case(17)"
    kind: str                          # "omni3" | "arm2"
    regions: list                      # [(K, T), ...]
    q0: np.ndarray
    v0: np.ndarray
    human: object                      # a sharedctl.human.HumanModel
    duration: float
    sharing: SharingParameters = field(default_factory=SharingParameters)
    notes: str = ""

    def feasible(self) -> FeasibleSet:
        return FeasibleSet.from_regions([Polytope.from_rows(K, T) for K, T in self.regions])

    def scenario_data(self) -> dict:
        """The scenario mapping (sharedctl/scenario.py schema) for this case's plant, set and
        initial state; the operator is swapped in afterwards (scenario files cannot express
        every operator the tests use)."""
        return {
            "name": self.label,
            "duration": self.duration,
            "dt": DT,
            "robot": {"kind": self.kind},
            "region": [{"K": [list(map(float, row)) for row in K], "T": list(map(float, T))} for K, T in self.regions],
            "initial": {"q": [float(x) for x in self.q0], "qdot": [float(x) for x in self.v0]},
            "desired": {"kind": "line", "velocity": [0.0] * len(self.q0)},
        }

    def loop(self, controller: str, sharing: SharingParameters | None = None) -> ClosedLoop:
        """The closed loop, built the way scenario files are (so the controller gets the
        plant's default gains), with this case's operator and sharing parameters."""
        loop, _, _ = parse(self.scenario_data()).closed_loop(controller)
        loop.human = self.human
        loop.sharing = sharing or self.sharing
        return loop

    def __repr__(self):
        return f"<{self.label}: {self.notes}>"


_RUNS: dict = {}


#: The 2-link arm's links have ~0.05 kg m² of inertia: with the operator's 20 N·m and the
#: laws' feedforward M v̇_ref growing like 1/|x| near a joint limit, a 2 ms RK4 step cannot
#: follow it (the arm cases diverged numerically at 2 ms, not in the continuous-time law).
#: A small arm is sampled faster, as real ones are (1 kHz and up).
ARM_DT = 5e-4


def case_dt(case: Case) -> float:
    return ARM_DT if case.kind == "arm2" else DT


def run(case: Case, controller: str, dt: float | None = None, sharing: SharingParameters | None = None,
        duration: float | None = None) -> Trace:
    """Simulate `case` under `controller` (cached by identity of the case and the arguments)."""
    dt = case_dt(case) if dt is None else dt
    key = (id(case), controller, dt, sharing, duration)
    if key not in _RUNS:
        loop = case.loop(controller, sharing)
        _RUNS[key] = (case, simulate(loop, case.q0, case.v0, duration or case.duration, dt))
    return _RUNS[key][1]


# ----- the packaged paper scenarios, shortened -----------------------------------------------
def paper_data(name: str) -> dict:
    """The packaged scenario file `name` (paper_convex / paper_nonconvex) as a dict."""
    return tomllib.loads(resources.files("sharedctl").joinpath(f"scenarios/{name}.toml").read_text())


# The packaged files run 20 s / 30 s and their first contact only comes at t ≈ 10.1 s
# (convex) and t ≈ 8.9 s (non-convex): their first 8 s never leave the safe set. The
# shortened variants keep every key of the file (set, q0, operator, gains) and only start
# the file's desired line later, at its position at t = PAPER_SHIFT — the same line, entered
# later — and run PAPER_DURATION (5 s convex, 17 s non-convex):
# * convex, shift 9.5 s: first machine take-over at ≈ 1.4 s on the face x = −1, the slide
#   along it and take-overs on y = 4 from ≈ 3 s, next to the corner x = −1, y = 4;
# * non-convex, shift 16 s (the line start (0.7, 0.6) is inside the obstacle, so the operator
#   pulls the robot from (−0.9, 3) straight at the face x = 0 at up to ≈ 2 m/s): the fail-safe
#   stop from that speed would end in the obstacle, so the machine takes over early (≈ 0.9 s,
#   0.8 m from the face), slides the robot down the face with the projected wish while the wish
#   is in the obstacle (along the face the law follows the wish at its own pace), hands it back
#   once the wish is below y = −ε and the push has turned away, and the operator rounds the
#   obstacle corner (0, 0) from {x ≤ 0} into {y ≤ 0} (≈ 16 s).
PAPER_SHIFT = {"paper_convex": 9.5, "paper_nonconvex": 16.0}
PAPER_DURATION = {"paper_convex": 5.0, "paper_nonconvex": 17.0}


def paper_short_data(name: str) -> dict:
    data = paper_data(name)
    t0 = PAPER_SHIFT[name]
    d = data["desired"]
    d["start"] = [s + v * t0 for s, v in zip(d["start"], d["velocity"])]
    data["duration"] = PAPER_DURATION[name]
    data["dt"] = DT
    data["name"] = f"{name}-shifted-{t0:g}s"
    return data


_PAPER: dict = {}


def paper_case(name: str, mode: str = "shared") -> Case:
    """The shortened paper scenario `name` as a Case (one object per name, so runs cache)."""
    key = (name, mode)
    if key not in _PAPER:
        data = paper_short_data(name)
        data.setdefault("sharing", {})["mode"] = mode
        scenario = parse(data)
        loop, q0, v0 = scenario.closed_loop("ce")
        regions = [(r["K"], r["T"]) for r in data["region"]]
        _PAPER[key] = Case(f"paper_case({name!r}, {mode!r})", "omni3", regions, q0, v0, loop.human,
                           scenario.duration, loop.sharing, data["name"])
    return _PAPER[key]


# ----- geometry helpers ----------------------------------------------------------------------
def polygon_rows(angles, offsets, centre):
    """Rows n_j·(p − c) ≤ d_j of a polygon in (x, y), lifted to q = [x, y, ψ] with ψ rows."""
    K, T = [], []
    for a, d in zip(angles, offsets):
        n = np.array([math.cos(a), math.sin(a)])
        K.append([n[0], n[1], 0.0])
        T.append(float(-n @ centre - d))
    return K + PSI_K, T + PSI_T


def slacks(K, T, q) -> np.ndarray:
    """−(K q + T) with unit rows: the distance of q to every face (positive inside)."""
    K = np.asarray(K, float)
    norms = np.linalg.norm(K, axis=1)
    return -(K @ q + np.asarray(T, float)) / norms


def planar_triple_clearance(K, T, dims: int) -> float:
    """min over points of the polytope of the 3rd-smallest face distance, over planar rows.

    With the value above b2, no point lies within b2 of three faces of one polytope at once,
    so at most two planar rows (plus one ψ row for omni3) can be hazardous together and one
    invertible group covers all of them.
    """
    K = np.asarray(K, float)[:, :dims]
    T = np.asarray(T, float)
    planar = [i for i in range(len(K)) if np.linalg.norm(K[i]) > 0.5]
    A = K[planar] / np.linalg.norm(K[planar], axis=1)[:, None]
    b = T[planar] / np.linalg.norm(np.asarray(K, float)[planar], axis=1)
    best = math.inf
    for trio in itertools.combinations(range(len(planar)), 3):
        # minimise s subject to  −(a_j p + b_j) ≤ s for j in trio,  a_i p + b_i ≤ 0 for all i
        c = np.zeros(dims + 1)
        c[-1] = 1.0
        A_ub = [np.append(-A[j], -1.0) for j in trio] + [np.append(A[i], 0.0) for i in range(len(A))]
        b_ub = [b[j] for j in trio] + [-b[i] for i in range(len(A))]
        res = linprog(c, A_ub=np.array(A_ub), b_ub=np.array(b_ub), bounds=[(None, None)] * (dims + 1))
        if res.status == 0:
            best = min(best, float(res.fun))
    return best


def common_slack(regions, dims: int = 2) -> float:
    """max over points p of the smallest planar slack with respect to every region at once
    (> 0: the regions overlap; the value is the radius of the largest disc in the overlap)."""
    A, b = [], []
    for K, T in regions:
        K = np.asarray(K, float)
        for row, t in zip(K, np.asarray(T, float)):
            if np.linalg.norm(row[:dims]) > 0.5:
                norm = np.linalg.norm(row)
                A.append(np.append(row[:dims] / norm, 1.0))   # a p + s ≤ −t
                b.append(-t / norm)
    c = np.zeros(dims + 1)
    c[-1] = -1.0
    res = linprog(c, A_ub=np.array(A), b_ub=np.array(b), bounds=[(None, None)] * dims + [(None, 100.0)])
    return float(-res.fun) if res.status == 0 else -math.inf


def is_bounded(K, dims: int = 2) -> bool:
    """Is {p : K p ≤ c} bounded for every c? (the planar normals positively span R^dims)."""
    K = np.asarray(K, float)
    A = np.array([row[:dims] for row in K if np.linalg.norm(row[:dims]) > 0.5])
    for angle in np.linspace(0, 2 * math.pi, 16, endpoint=False):
        d = np.array([math.cos(angle), math.sin(angle)])
        res = linprog(-d, A_ub=A, b_ub=np.ones(len(A)), bounds=[(None, None)] * dims)
        if res.status != 0:
            return False
    return True


def check_band_assumptions(case: Case, bands: Bands = BANDS) -> None:
    """Raise AssertionError if a generated set breaks the assumptions of the test docstring."""
    dims = 2
    for K, T in case.regions:
        clearance = planar_triple_clearance(K, T, dims)
        assert clearance > bands.b2, f"{case.label}: three faces within {clearance:.3f} of one point"


def random_polygon(rng: np.random.Generator, faces: int, centre) -> tuple[np.ndarray, np.ndarray]:
    """Outward normals at random angles with consecutive gaps in [40°, 150°] (so they
    positively span the plane: the polygon is bounded) and offsets 1.0–3.0 m from `centre`."""
    while True:
        gaps = rng.uniform(40.0, 150.0, size=faces)
        gaps *= 360.0 / gaps.sum()
        if gaps.min() >= 40.0 and gaps.max() <= 150.0:
            break
    angles = np.radians(rng.uniform(0, 360) + np.concatenate([[0.0], np.cumsum(gaps[:-1])]))
    offsets = rng.uniform(1.0, 3.0, size=faces)
    return angles, offsets


def first_exit_time(regions, trajectory, horizon: float, step: float = 0.02) -> float | None:
    """The first time the desired trajectory leaves the union, or None within `horizon`."""
    times = np.arange(0.0, horizon, step)
    qd = np.array([trajectory.sample(float(t)).q for t in times])
    inside = np.zeros(times.size, dtype=bool)
    for K, T in regions:
        inside |= np.all(qd @ np.asarray(K, float).T + np.asarray(T, float) < 0.0, axis=1)
    out = np.flatnonzero(~inside)
    return float(times[out[0]]) if out.size else None


def scripted(trajectory, n: int):
    return ScriptedOperator(trajectory, np.full(n, KP), np.full(n, KD))


def line_leaving(rng, regions, q0, n_planar: int, speed_range=(0.1, 0.4), max_exit=5.0):
    """A line from q0 at 0.1–0.4 m/s in a random direction that leaves the set within max_exit s."""
    for _ in range(200):
        a = rng.uniform(0, 2 * math.pi)
        speed = rng.uniform(*speed_range)
        vel = np.zeros(q0.size)
        vel[:2] = speed * np.array([math.cos(a), math.sin(a)])
        traj = LineTrajectory(q0.copy(), vel)
        t_exit = first_exit_time(regions, traj, max_exit)
        if t_exit is not None:
            return traj, t_exit
    raise AssertionError("no leaving line found")


# ----- omnidirectional robot: random convex sets -------------------------------------------------
def _interior_point(rng, regions, min_slack: float, box: float = 6.0):
    for _ in range(10_000):
        q = np.array([rng.uniform(-box, box), rng.uniform(-box, box), 0.0])
        if np.all(slacks(*regions[0], q) >= min_slack):
            return q
    raise AssertionError("no interior point")


@functools.lru_cache(maxsize=None)
def random_convex_case(seed: int) -> Case:
    """A random convex polygon (3–5 faces) × |ψ| ≤ π/2, q0 with slack ≥ 0.4, |v0| ≤ 0.3,
    and a desired line (0.1–0.4 m/s) or circle that leaves it; a scripted operator."""
    rng = np.random.default_rng(seed)
    while True:
        faces = int(rng.integers(3, 6))
        centre = rng.uniform(-2, 2, size=2)
        angles, offsets = random_polygon(rng, faces, centre)
        regions = [polygon_rows(angles, offsets, centre)]
        q0 = _interior_point(rng, regions, 0.4)
        v0 = np.zeros(3)
        v0[:2] = rng.uniform(-1, 1, size=2)
        v0[:2] *= rng.uniform(0, 0.3) / max(np.linalg.norm(v0[:2]), 1e-9)
        if rng.uniform() < 0.6:
            try:
                traj, t_exit = line_leaving(rng, regions, q0, 2, max_exit=4.0)
            except AssertionError:
                continue
            shape = "line"
        else:
            # a circle through q0 that crosses a face: radius 0.6–2.5 m, speed 0.1–0.4 m/s
            r = rng.uniform(0.6, 2.5)
            phase = rng.uniform(0, 2 * math.pi)
            omega = rng.choice([-1, 1]) * rng.uniform(0.1, 0.4) / r
            centre_c = q0[:2] - r * np.array([math.cos(phase), math.sin(phase)])
            traj = CircleTrajectory(3, centre_c, r, omega, phase)
            t_exit = first_exit_time(regions, traj, 4.0)
            shape = "circle"
            if t_exit is None:
                continue
        case = Case(f"random_convex_case({seed})", "omni3", regions, q0, v0, scripted(traj, 3),
                    duration=float(max(3.0, t_exit + 2.0)),
                    notes=f"{faces} faces, {shape}, exit at {t_exit:.2f} s")
        try:
            check_band_assumptions(case)
        except AssertionError:
            continue
        return case


@functools.lru_cache(maxsize=None)
def random_union_case(seed: int) -> Case:
    """Two overlapping rectangles forming an L or a T (rotated by a random angle): A is
    2–4 m × 5–8 m, B stands on it (2–4 m wide, 5–8 m tall, so it rises ≥ 1 m above A).
    q0 lies in A with slack ≥ 0.4 m from A's faces, |v0| ≤ 0.3 m/s, and the desired line
    (0.1–0.4 m/s) aims at a point of the notch beside B — the part of the plane neither
    rectangle covers — so it leaves the union through the inner faces, near the re-entrant
    corner, within 5 s."""
    rng = np.random.default_rng(seed)
    while True:
        rot = rng.uniform(0, 2 * math.pi)
        R = np.array([[math.cos(rot), -math.sin(rot)], [math.sin(rot), math.cos(rot)]])
        wa, la = rng.uniform(2.0, 4.0), rng.uniform(5.0, 8.0)
        wb, lb = rng.uniform(2.0, 4.0), rng.uniform(wa + 1.0, 8.0)
        shift = rng.uniform(0.0, la - wb)                  # where B stands along A
        ca, cb = np.array([la / 2, wa / 2]), np.array([shift + wb / 2, lb / 2])
        regions = []
        for c, hx, hy in ((ca, la / 2, wa / 2), (cb, wb / 2, lb / 2)):
            angles = [rot, rot + HALF_PI, rot + math.pi, rot + 3 * HALF_PI]
            regions.append(polygon_rows(angles, [hx, hy, hx, hy], R @ c))
        notches = [(0.0, shift), (shift + wb, la)]
        lo, hi = max(notches, key=lambda n: n[1] - n[0])
        if hi - lo < 0.6:
            continue
        target_local = np.array([rng.uniform(lo, hi), rng.uniform(wa + 0.2, min(lb, wa + 1.5))])
        for _ in range(50):
            local = np.array([rng.uniform(0.4, la - 0.4), rng.uniform(0.4, wa - 0.4)])
            q0 = np.array([*(R @ local), 0.0])
            direction = R @ (target_local - local)
            speed = rng.uniform(0.1, 0.4)
            vel = np.zeros(3)
            vel[:2] = speed * direction / np.linalg.norm(direction)
            traj = LineTrajectory(q0.copy(), vel)
            t_exit = first_exit_time(regions, traj, 5.0)
            if t_exit is not None and np.all(slacks(*regions[0], q0) >= 0.4):
                break
        else:
            continue
        v0 = np.zeros(3)
        v0[:2] = rng.uniform(-1, 1, size=2)
        v0[:2] *= rng.uniform(0, 0.3) / max(np.linalg.norm(v0[:2]), 1e-9)
        case = Case(f"random_union_case({seed})", "omni3", regions, q0, v0, scripted(traj, 3),
                    duration=float(min(8.0, t_exit + 2.0)),
                    notes=f"rot {math.degrees(rot):.0f}°, A {la:.1f}×{wa:.1f}, B {wb:.1f}×{lb:.1f} at {shift:.1f}, "
                          f"exit at {t_exit:.2f} s")
        try:
            check_band_assumptions(case)
        except AssertionError:
            continue
        return case


# ----- adversarial operators -------------------------------------------------------------------
def nearest_face_normal(regions, q):
    """The unit outward normal (in R^n) of the face of the first region closest to q."""
    K, T = regions[0]
    s = slacks(K, T, q)
    planar = [i for i in range(len(K)) if np.linalg.norm(np.asarray(K[i], float)[:2]) > 0.5]
    j = min(planar, key=lambda i: s[i])
    n = np.asarray(K[j], float)
    return n / np.linalg.norm(n), float(s[j])


@functools.lru_cache(maxsize=None)
def adversarial_case(seed: int) -> Case:
    """A random convex polygon and an ArbitraryOperator that pushes to leave it:
    either a constant 50–200 N towards a face, a bang-bang force (±, switching every
    0.2–0.6 s) along a face normal, or random forces (≤ 200 N, ≤ 10 N·m about ψ) re-drawn
    every 0.2 s. The desired trajectory the machine sees is a line leaving the set."""
    base = random_convex_case(seed)
    rng = np.random.default_rng(seed + 1_000_003)
    regions, q0 = base.regions, base.q0
    normal, _ = nearest_face_normal(regions, q0)
    style = ["constant", "bang-bang", "random"][int(rng.integers(0, 3))]
    magnitude = rng.uniform(50.0, 200.0)
    if style == "constant":
        force = magnitude * normal
        fn = lambda t, q, v, f=force: f  # noqa: E731 — the push as one expression per style
    elif style == "bang-bang":
        period = rng.uniform(0.2, 0.6)
        force = magnitude * normal
        fn = lambda t, q, v, f=force, p=period: f if int(t / p) % 2 == 0 else -0.5 * f  # noqa: E731 — the push as one expression per style
    else:
        times = np.arange(0.0, 10.0, 0.2)
        forces = np.zeros((times.size, 3))
        forces[:, :2] = rng.uniform(-1, 1, size=(times.size, 2))
        forces[:, :2] *= (rng.uniform(50.0, 200.0, times.size) / np.linalg.norm(forces[:, :2], axis=1))[:, None]
        forces[:, 2] = rng.uniform(-10.0, 10.0, times.size)
        fn = lambda t, q, v, ts=times, fs=forces: fs[min(int(t / 0.2), len(fs) - 1)]  # noqa: E731 — the push as one expression per style
    human = ArbitraryOperator(base.human.trajectory, np.full(3, KP), function=fn)
    return Case(f"adversarial_case({seed})", "omni3", regions, q0, base.v0, human, duration=4.0,
                notes=f"{style} push {magnitude:.0f} N; base {base.notes}")


def rectangle(x_lo, x_hi, y_lo, y_hi):
    """x_lo ≤ x ≤ x_hi, y_lo ≤ y ≤ y_hi, |ψ| ≤ π/2 as (K, T)."""
    K = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]] + PSI_K
    return K, [-x_hi, x_lo, -y_hi, y_lo] + PSI_T


@functools.lru_cache(maxsize=None)
def push_case(force: float = 100.0, duration: float = 3.0) -> Case:
    """An operator who leans on the face x = 0 with a constant `force` (N) from rest at
    x = −0.5 m (set −3 ≤ x ≤ 0, −3 ≤ y ≤ 3): the situation in which a sharing law without a
    minimum dwell chatters (each machine push makes the state safe, the operator pushes back)."""
    q0 = np.array([-0.5, 0.0, 0.0])
    push = np.array([force, 0.0, 0.0])
    human = ArbitraryOperator(LineTrajectory(q0.copy(), np.array([0.3, 0.0, 0.0])), np.full(3, KP),
                              function=lambda t, q, v, f=push: f)
    return Case(f"push_case({force}, {duration})", "omni3", [rectangle(-3.0, 0.0, -3.0, 3.0)], q0,
                np.zeros(3), human, duration, notes=f"constant {force} N into x = 0")


@functools.lru_cache(maxsize=None)
def creep_case(distance: float, speed: float) -> Case:
    """A slow approach: `distance` (m) from the face x = 0 of −3 ≤ x ≤ 0, −3 ≤ y ≤ 3, moving
    towards it at `speed` (m/s), the operator's desired line continuing through the face at
    the same speed. Definition 2 lets such a state creep until ẋ ≥ f_b1(x), i.e. to
    |x| = s·b1²/(1 + s·b1) (s = speed), before the machine is given authority."""
    q0 = np.array([-distance, 0.0, 0.0])
    v = np.array([speed, 0.0, 0.0])
    traj = LineTrajectory(q0.copy(), v.copy())
    return Case(f"creep_case({distance}, {speed})", "omni3", [rectangle(-3.0, 0.0, -3.0, 3.0)], q0, v,
                scripted(traj, 3), float(min(6.0, distance / speed + 1.5)),
                notes=f"{speed} m/s into x = 0 from {distance} m")


def first_takeover_distance(speed: float, bands: Bands = BANDS) -> float:
    """|x| at which an approach at ẋ = speed first becomes hazardous: ẋ ≥ f_b1(x) at
    s·b1²/(1 + s·b1) (Definition 2), or any approach inside the inner band b0 — the larger."""
    return max(speed * bands.b1**2 / (1.0 + speed * bands.b1), bands.b0)


@functools.lru_cache(maxsize=None)
def fast_approach_case(seed: int) -> Case:
    """Start 0.5 m from a face of a random polygon moving towards it at 1–3 m/s (normal
    component), with a scripted operator whose desired line continues through that face."""
    rng = np.random.default_rng(seed + 7_777)
    base_seed = seed
    while True:
        base = random_convex_case(base_seed)
        K, T = base.regions[0]
        planar = [i for i in range(len(K)) if np.linalg.norm(np.asarray(K[i], float)[:2]) > 0.5]
        j = int(rng.choice(planar))
        n = np.asarray(K[j], float)[:2]
        # a point at distance 0.5 from face j and ≥ 0.6 from every other planar face
        q0 = None
        for _ in range(2000):
            cand = np.array([*rng.uniform(-8, 8, 2), 0.0])
            cand[:2] += (slacks(K, T, cand)[j] - 0.5) * n      # onto the 0.5 m line of face j
            s = slacks(K, T, cand)
            if np.all(np.delete(s[planar], planar.index(j)) >= 0.6):
                q0 = cand
                break
        if q0 is None:
            base_seed = int(rng.integers(0, 2**31 - 1))
            continue
        speed = rng.uniform(1.0, 3.0)
        tangential = rng.uniform(-0.5, 0.5)
        v0 = np.zeros(3)
        v0[:2] = speed * n + tangential * np.array([-n[1], n[0]])
        vel = np.zeros(3)
        vel[:2] = 0.3 * n
        traj = LineTrajectory(q0.copy(), vel)
        return Case(f"fast_approach_case({seed})", "omni3", base.regions, q0, v0, scripted(traj, 3),
                    duration=3.0, notes=f"{speed:.2f} m/s into face {j} from 0.5 m, polygon {base.label}")


# ----- the planar arm ----------------------------------------------------------------------------
def box_rows(lo, hi):
    """lo ≤ q ≤ hi as rows K q + T ≤ 0 (two joints)."""
    K = [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]]
    T = [-hi[0], lo[0], -hi[1], lo[1]]
    return K, T


def arm_case(label, regions, q0, v0, traj, duration, notes="") -> Case:
    return Case(label, "arm2", regions, np.asarray(q0, float), np.asarray(v0, float), scripted(traj, 2),
                duration, notes=notes)


ARM_BOX = box_rows([-0.8, -0.3], [1.2, 2.0])     # −0.8 ≤ q1 ≤ 1.2, −0.3 ≤ q2 ≤ 2.0 (rad)
ARM_Q0 = np.array([0.2, 0.8])


@functools.lru_cache(maxsize=None)
def arm_box_case(velocity) -> Case:
    """The joint box ARM_BOX from q0 = (0.2, 0.8) rad at rest, the desired line from q0 at
    `velocity` (rad/s) leaving it."""
    traj = LineTrajectory(ARM_Q0.copy(), np.asarray(velocity, float))
    t_exit = first_exit_time([ARM_BOX], traj, 10.0)
    return arm_case(f"arm_box_case({tuple(velocity)})", [ARM_BOX], ARM_Q0, [0.0, 0.0], traj,
                    float(t_exit + 2.0), notes=f"line leaves at {t_exit:.2f} s")


@functools.lru_cache(maxsize=None)
def arm_union_case() -> Case:
    """A non-convex joint set: the union of −0.8 ≤ q1 ≤ 1.2, −0.3 ≤ q2 ≤ 0.7 and
    −0.8 ≤ q1 ≤ 0.4, −0.3 ≤ q2 ≤ 2.0 (an L), starting in the lower box with the desired
    line heading into the missing corner q1 > 0.4, q2 > 0.7."""
    regions = [box_rows([-0.8, -0.3], [1.2, 0.7]), box_rows([-0.8, -0.3], [0.4, 2.0])]
    q0 = np.array([0.0, 0.2])
    traj = LineTrajectory(q0.copy(), np.array([0.3, 0.3]))
    t_exit = first_exit_time(regions, traj, 10.0)
    return arm_case("arm_union_case()", regions, q0, [0.0, 0.0], traj, float(t_exit + 2.0),
                    notes=f"L of two boxes, line leaves at {t_exit:.2f} s")


@functools.lru_cache(maxsize=None)
def random_arm_box_case(seed: int) -> Case:
    """A random joint box (each side 2.0–3.0 rad, inside the reachable range), q0 with slack
    ≥ 0.4 rad, |q̇0| ≤ 0.3 rad/s, and a desired line (0.2–0.6 rad/s) leaving it in ≤ 4 s."""
    rng = np.random.default_rng(seed)
    while True:
        lo = np.array([rng.uniform(-1.2, 0.0), rng.uniform(-0.8, 0.4)])
        hi = lo + rng.uniform(2.0, 3.0, size=2)
        regions = [box_rows(lo, hi)]
        q0 = lo + 0.4 + rng.uniform(0, 1, 2) * (hi - lo - 0.8)
        v0 = rng.uniform(-1, 1, 2)
        v0 *= rng.uniform(0, 0.3) / max(np.linalg.norm(v0), 1e-9)
        a = rng.uniform(0, 2 * math.pi)
        vel = rng.uniform(0.2, 0.6) * np.array([math.cos(a), math.sin(a)])
        traj = LineTrajectory(q0.copy(), vel)
        t_exit = first_exit_time(regions, traj, 4.0)
        if t_exit is None:
            continue
        return arm_case(f"random_arm_box_case({seed})", regions, q0, v0, traj, float(t_exit + 2.0),
                        notes=f"box {np.round(lo, 2)}..{np.round(hi, 2)}")


# ----- property checks shared by the test modules -------------------------------------------------
def describe(case: Case, controller: str, trace: Trace, k: int | None = None) -> str:
    where = "" if k is None else f" at t={trace.t[k]:.3f} s q={np.round(trace.q[k], 4)} v={np.round(trace.v[k], 3)}"
    return f"{case.label} [{case.notes}] controller={controller}{where}"


def invariance_failure(case: Case, controller: str, trace: Trace, dt: float | None = None) -> str | None:
    """None when the run stayed inside, finite and complete; otherwise what went wrong."""
    dt = case_dt(case) if dt is None else dt
    steps = int(round(case.duration / dt))
    if not trace.finite:
        return f"non-finite state after {trace.t.size} steps: " + describe(case, controller, trace, trace.t.size - 1)
    if trace.t.size != steps:
        last, ok = trace.t.size - 1, np.flatnonzero(decided(trace))
        k = int(ok[-1]) if ok.size else 0
        return (f"stopped after {trace.t.size} of {steps} steps (the state left the active group's "
                f"polytope: last q={np.round(trace.q[last], 4)}, margin {trace.margin[last]:.3g}); last decided "
                f"sample: authority {Authority(trace.authority[k]).name}, class {SetClass(trace.set_class[k]).name}, "
                f"group {trace.group[k]}, role {trace.role[k]}, v̂={np.round(trace.v_hat[k], 3)}: "
                + describe(case, controller, trace, k))
    for name in ("q", "v", "u_s"):
        if not np.all(np.isfinite(getattr(trace, name))):
            return f"non-finite {name}: " + describe(case, controller, trace)
    outside = np.flatnonzero(~trace.inside)
    if outside.size:
        k = int(outside[0])
        return (f"{outside.size} samples outside, first at margin {trace.margin[k]:.4g}: "
                + describe(case, controller, trace, k))
    return None


def decided(trace: Trace) -> np.ndarray:
    """Samples the arbiter decided (a run that escapes its group ends with one state-only row)."""
    return trace.authority >= 0


def takeover_samples(trace: Trace) -> np.ndarray:
    """Samples where k_s went 1 → 0 (authority HUMAN → SHARED/MACHINE); sample 0 counts
    when the machine holds authority from the start (k_s starts at 1 in shared mode)."""
    human = trace.authority == int(Authority.HUMAN)
    machine = decided(trace) & ~human
    later = np.flatnonzero(human[:-1] & machine[1:]) + 1
    return np.concatenate([[0], later]) if machine.size and machine[0] else later


def release_samples(trace: Trace) -> np.ndarray:
    """Samples where k_s went 0 → 1 (authority SHARED/MACHINE → HUMAN)."""
    human = trace.authority == int(Authority.HUMAN)
    machine = decided(trace) & ~human
    return np.flatnonzero(machine[:-1] & human[1:]) + 1


def transparency_failures(trace: Trace) -> list[str]:
    """Authority HUMAN ⇒ u_s == u_h, value for value."""
    for k in np.flatnonzero(trace.authority == int(Authority.HUMAN)):
        if not np.array_equal(trace.u_s[k], trace.u_h[k]):
            return [f"HUMAN but u_s={trace.u_s[k]} != u_h={trace.u_h[k]} at t={trace.t[k]:.3f}"]
    return []


def braking_distance(block, speed: float) -> float:
    """The path from `speed` to rest at deceleration a_c + k·speed, integrated numerically
    (dx = −v dv / (a_c + k v)): the oracle for BrakeBlock.distance's closed form."""
    if speed <= 0.0:
        return 0.0
    return integrate.quad(lambda u: u / (block.coulomb + block.viscous * u), 0.0, speed)[0]


def stop_reach_bound(backup, v, a=None) -> float:
    """An upper bound of how far any unit-norm row can advance in the fail-safe stop from velocity
    v with the acceleration a held T_w (default: none): per brake block, |v_b| T_w + ½|a_b| T_w²
    (the hold) plus the braking path from |v_b| + |a_b| T_w (numerically integrated, plus the
    block's creep) — path lengths, whatever the direction."""
    if backup is None:
        return 0.0
    v = np.asarray(v, float)
    a = np.zeros_like(v) if a is None else np.asarray(a, float)
    T, total = backup.hold, 0.0
    for b in backup.blocks:
        speed, accel = float(np.linalg.norm(v[list(b.axes)])), float(np.linalg.norm(a[list(b.axes)]))
        top = speed + accel * T
        total += speed * T + 0.5 * accel * T * T + braking_distance(b, top) + (b.creep if top > 0.0 else 0.0)
    return total


def takeover_margin_failures(trace: Trace, params: SharingParameters, backup=None, model=None) -> list[str]:
    """Every take-over within b1 of the border — b1 plus the fail-safe stop's reach at that
    sample's velocity (the controller's: v̂ in output feedback) with the operator's command held
    when the loop has a backup model (and `model` to turn u_h into an acceleration):
    trace.margin ≤ b1 + reach at each take-over sample.

    Geometry, not the arbiter's classification: a take-over needs a hazardous state, i.e. a row
    with −b1 ≤ x_j + reach_j < 0 in every polytope that contains q (or none contains q), so the
    best region's slack (FeasibleSet.margin, from the rows alone) is at most b1 + reach there."""
    b1 = params.bands.b1
    for k in takeover_samples(trace):
        held = model.acceleration(trace.q[k], trace.v_hat[k], trace.u_h[k]) if backup is not None else None
        limit = b1 + stop_reach_bound(backup, trace.v_hat[k], held)
        if not trace.margin[k] <= limit + 1e-12:
            return [f"take-over at t={trace.t[k]:.3f} with margin {trace.margin[k]:.4g} > b1 + reach = {limit:.4g}"]
    return []


def dwell_failures(trace: Trace, params: SharingParameters, dt: float) -> list[str]:
    """Every release at least ⌈Δt/dt⌉ samples after its take-over (Δt = min_machine_dwell, counted
    in samples of the trace; the arbiter sums dt, so its release may come one sample later, never earlier)."""
    takeovers = takeover_samples(trace)
    shortest = math.ceil(params.min_machine_dwell / dt - 1e-9)
    for k in release_samples(trace):
        before = takeovers[takeovers < k]
        if before.size and k - before[-1] < shortest:
            return [f"release at t={trace.t[k]:.3f}, {(k - before[-1]) * dt:.4f} s after the take-over "
                    f"(dwell {params.min_machine_dwell} s)"]
    return []


def sharing_failures(trace: Trace, params: SharingParameters, dt: float, backup=None, model=None) -> list[str]:
    """The closed-loop sharing properties that need no classification of the state (see the
    functions above); the decisions per set class are tested on hand-classified states in
    tests/test_sharing_properties.py."""
    return (transparency_failures(trace) + takeover_margin_failures(trace, params, backup, model)
            + dwell_failures(trace, params, dt))


# ----- hypothesis strategies ------------------------------------------------------------------
# Settings for simulation-backed properties: few examples (a run costs ~1–4 s), no shrinking
# (a case is a seed: shrinking would only re-run simulations), a deterministic choice of
# seeds and no example database.
SIM_SETTINGS = dict(
    deadline=None, derandomize=True, database=None, phases=[Phase.explicit, Phase.generate],
    report_multiple_bugs=False, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
seeds = st.integers(min_value=0, max_value=2**31 - 1)
convex_cases = seeds.map(random_convex_case)
union_cases = seeds.map(random_union_case)
adversarial_cases = seeds.map(adversarial_case)
fast_approach_cases = seeds.map(fast_approach_case)
arm_box_cases = seeds.map(random_arm_box_case)
controllers = st.sampled_from(CONTROLLERS)


# ----- operators for the fault-envelope properties (tests/test_fault_envelope_properties.py) ------
# Both drive the handle within the joystick's range (|deflection| ≤ 1 per coordinate, as the wire
# carries it), with a spring constant k_p of 20–60 N per unit deflection.
OPERATOR_KP = (20.0, 60.0)


def _push_towards(target: np.ndarray, kp: float):
    """u_h(t, q, v) = k_p d with d the direction to `target` in (x, y), the larger coordinate at full
    deflection (less within 1 m of the target), and ψ turned back towards 0."""
    def push(t, q, v, target=target, kp=kp):
        d = np.zeros(3)
        gap = target[:2] - np.asarray(q, float)[:2]
        d[:2] = gap / max(1.0, float(np.max(np.abs(gap))))
        d[2] = float(np.clip(-q[2], -1.0, 1.0))
        return kp * d
    return push


def face_rush_operator(case: Case, seed: int) -> tuple[ArbitraryOperator, str]:
    """An operator who drives at a face and ignores what the robot does: full deflection towards a
    point 1 m beyond the face — the one the case's own desired trajectory first leaves through, or
    a random face of a random polytope (1 m out along its normal from q0's foot on it, shifted up to
    1 m along it) — so the robot reaches the face at the speed the set lets it gather. The wish the
    machine sees is that point, fixed. Returns the operator and a line describing it."""
    rng = np.random.default_rng(seed + 2_000_003)
    kp = rng.uniform(*OPERATOR_KP)
    q0 = np.asarray(case.q0, float)
    t_exit = first_exit_time(case.regions, case.human.trajectory, 12.0)
    if rng.uniform() < 0.5 and t_exit is not None:
        exit_point = case.human.trajectory.sample(t_exit).q[:2]
        heading = exit_point - q0[:2]
        target_xy = exit_point + heading / max(float(np.linalg.norm(heading)), 1e-9)
        aim = "the desired line's exit"
    else:
        r = int(rng.integers(0, len(case.regions)))
        K, T = (np.asarray(x, float) for x in case.regions[r])
        planar = [i for i in range(len(K)) if np.linalg.norm(K[i, :2]) > 0.5]
        j = int(rng.choice(planar))
        n = K[j, :2] / np.linalg.norm(K[j, :2])
        foot = q0[:2] - (float(K[j] @ q0) + T[j]) / float(np.linalg.norm(K[j, :2])) * n
        target_xy = foot + n + rng.uniform(-1.0, 1.0) * np.array([-n[1], n[0]])
        aim = f"face {j} of polytope {r}"
    target = np.array([target_xy[0], target_xy[1], 0.0])
    operator = ArbitraryOperator(LineTrajectory(target.copy(), np.zeros(3)), np.full(3, kp),
                                 function=_push_towards(target, kp))
    return operator, f"rush at {aim} ({np.round(target_xy, 2)}), k_p {kp:.0f}"


def random_deflection_operator(case: Case, seed: int) -> tuple[ArbitraryOperator, str]:
    """An operator who moves the handle at random: a deflection uniform in [−1, 1] per coordinate
    (ψ: [−0.3, 0.3]), re-drawn every 0.1–0.5 s and held in between (no damping: the speed wanders);
    the wish the machine sees is the case's own desired trajectory. Returns the operator and a line
    describing it."""
    rng = np.random.default_rng(seed + 3_000_017)
    kp = rng.uniform(*OPERATOR_KP)
    hold = rng.uniform(0.1, 0.5)
    times = np.arange(0.0, 12.0, hold)
    deflections = rng.uniform(-1.0, 1.0, size=(times.size, 3))
    deflections[:, 2] *= 0.3
    operator = ArbitraryOperator(case.human.trajectory, np.full(3, kp), times=times, forces=kp * deflections)
    return operator, f"random deflections every {hold:.2f} s, k_p {kp:.0f}"
