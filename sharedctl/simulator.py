"""Fixed-step, deterministic closed-loop simulation: plant + sharing + machine law + observer.

The continuous state is [q, q̇, θ̂, law state, observer state]. Every step of length dt:

1. the sharing function (sharing.py) samples the state and decides authority, group, law
   role and the blend weights — a hybrid system's discrete part, held over the step; with a
   backup model, so is the governor's share λ (backup.govern, found from the step's start);
2. the continuous part is integrated by one classical Runge–Kutta-4 step with the law
   evaluated at every stage (so Lyapunov identities hold to integration accuracy); a step
   too long for the stiffness the law gives the loop is replaced by two half steps (`_advance`),
   the discrete part still held.

When the machine takes over, or changes group or law, the law's filters restart from its
published initial conditions ((15), (26), (28)) and the shared estimate θ̂ carries over
(θ̂ + β when leaving (13)). θ̂ adapts only while the machine has full authority: under a
blended or human input the adaptation laws' premises (u = u_f) do not hold. A law's filters
integrate whenever it is engaged, with the input the plant receives (u_s at every RK stage,
`MachineLaw.with_applied_input`): the composite law's identity holds for any input.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .backup import BackupModel, govern, speed_aware_rows
from .constraints import FeasibleSet
from .controllers import (
    Adaptation,
    CertaintyEquivalentLaw,
    CompositeAdaptiveLaw,
    MachineLaw,
    OutputFeedbackBarrierLaw,
    OutputFeedbackLaw,
    VelocityObserver,
)
from .human import HumanModel
from .models import EulerLagrangeModel
from .reference import ReferenceShape
from .sets import classify
from .sharing import (
    ArbiterState,
    Authority,
    LawRole,
    Mode,
    SharingParameters,
    arbitrate,
    operator_pushes,
    select_group,
    shared_input,
    push_turned_away,
    wish_admissible,
)
from .transform import all_groups, coordinates


@dataclass
class MachineController:
    """The machine side: the tracking law, the law for the hazardous set (the same object when one
    law serves both roles), and the observer."""

    tracking: MachineLaw
    hazard: MachineLaw
    observer: VelocityObserver | None = None

    @property
    def name(self) -> str:
        return self.tracking.name

    @property
    def kind(self) -> str:
        """The configuration ("ce", "nce", "of"): the tracking law's. A law of another
        configuration in either role (a fallback) is not the configuration's own."""
        return self.tracking.configuration

    def owns(self, law: MachineLaw | None) -> bool:
        """Whether `law` belongs to this configuration (the `own_law` of a trace)."""
        return law is not None and law.configuration == self.kind

    def law(self, role: LawRole) -> MachineLaw:
        return self.hazard if role is LawRole.HAZARD else self.tracking


def make_controller(kind: str, gains: dict | None = None, model: EulerLagrangeModel | None = None) -> MachineController:
    """`ce` → (12) everywhere; `nce` → the composite law (12) + prediction error on (14)–(15)'s
    filters everywhere (docs/control.md §4.2); `of` → (25) with the observer (40), and the
    bounded-gain barrier law on the observer's v̂ in the hazardous set (docs/control.md §4.3).

    `gains` maps a law ("ce", "nce", "of", "of_barrier", "observer") to keyword overrides; they are
    laid over the model's `default_gains` (gains scale with the plant's inertia). The composite law's
    (12) part (K_p, λ_q, γ_θ) takes the "ce" table, and the "nce" table over it; the OF barrier
    law takes the "of_barrier" table (K_p, λ, γ_θ, barrier_weight). The "adaptation" table (σ₀ and the
    boxes of the robust update, controllers/adaptation.py) is every law's: one robot, one θ.
    """
    merged = {k: dict(v) for k, v in getattr(model, "default_gains", {}).items()}
    for law, table in (gains or {}).items():
        merged.setdefault(law, {}).update(table)
    gains = merged
    adaptation = Adaptation(**gains.get("adaptation", {}))
    if model is not None:
        adaptation.boxes(model)                      # the boxes' sizes and nesting, checked once
    ce = CertaintyEquivalentLaw(**gains.get("ce", {}), adaptation=adaptation)
    if kind == "ce":
        return MachineController(ce, ce)
    if kind == "nce":
        nce = CompositeAdaptiveLaw(**{**gains.get("ce", {}), **gains.get("nce", {})}, adaptation=adaptation)
        return MachineController(nce, nce)
    if kind == "of":
        of = OutputFeedbackLaw(**gains.get("of", {}), adaptation=adaptation)
        barrier = OutputFeedbackBarrierLaw(**gains.get("of_barrier", {}), adaptation=adaptation)
        return MachineController(of, barrier, VelocityObserver(**gains.get("observer", {})))
    raise ValueError(f"unknown controller {kind!r} (expected ce, nce or of)")


@dataclass
class ClosedLoop:
    """Everything one simulation needs."""

    model: EulerLagrangeModel
    feasible: FeasibleSet
    human: HumanModel
    controller: MachineController
    sharing: SharingParameters = field(default_factory=SharingParameters)
    reference: ReferenceShape = field(default_factory=ReferenceShape)
    theta_hat0: np.ndarray | None = None
    backup: BackupModel | None = None     # the fail-safe stop the commands are kept safe for (backup.py)


@dataclass
class Trace:
    """Sampled signals, one row per step (at the start of the step)."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    v_hat: np.ndarray
    q_d: np.ndarray
    q_r: np.ndarray
    u_h: np.ndarray
    u_f: np.ndarray
    u_s: np.ndarray
    tau: np.ndarray
    theta_hat: np.ndarray
    authority: np.ndarray
    set_class: np.ndarray
    group: np.ndarray
    role: np.ndarray
    k_h: np.ndarray
    k_f: np.ndarray
    intent: np.ndarray
    margin: np.ndarray
    inside: np.ndarray
    finite: bool
    switches: int
    group_switches: int
    # None where the producer of the trace does not know them:
    true_class: np.ndarray | None = None   # SetClass of the true (q, q̇) (Definition 2), −1 where no input was recorded
    own_law: np.ndarray | None = None      # u_f came from a law of the configuration (MachineController.owns)
    wish_inside: np.ndarray | None = None  # the operator's wish was admissible (sharing.wish_admissible)
    theta: np.ndarray | None = None        # the plant's true θ


class _Recorder:
    def __init__(self, steps, n, n_theta, optional=()):
        """`optional`: which of true_class, own_law, wish_inside the caller records (the others stay None
        in the Trace)."""
        def z(*shape):
            return np.full((steps,) + shape, np.nan)

        self.cols = {k: z(n) for k in ("q", "v", "v_hat", "q_d", "q_r", "u_h", "u_f", "u_s", "tau")}
        self.cols["theta_hat"] = z(n_theta)
        for k in ("t", "k_h", "k_f", "intent", "margin"):
            self.cols[k] = z()
        for k in ("authority", "set_class", "group", "role"):
            self.cols[k] = np.full(steps, -1, dtype=int)
        self.cols["inside"] = np.zeros(steps, dtype=bool)
        if "true_class" in optional:
            self.cols["true_class"] = np.full(steps, -1, dtype=int)
        for name in ("own_law", "wish_inside"):
            if name in optional:
                self.cols[name] = np.zeros(steps, dtype=bool)

    def put(self, k, **values):
        for name, value in values.items():
            self.cols[name][k] = value

    def trace(self, steps, finite, switches, group_switches, theta=None) -> Trace:
        cols = {name: arr[:steps] for name, arr in self.cols.items()}
        return Trace(**cols, finite=finite, switches=switches, group_switches=group_switches, theta=theta)


def simulate(loop: ClosedLoop, q0, v0, duration: float, dt: float) -> Trace:
    """Run the closed loop from (q0, q̇0) for `duration` seconds with step `dt`."""
    model, feasible, human, ctrl = loop.model, loop.feasible, loop.human, loop.controller
    n, n_theta = model.n, model.n_theta
    steps = int(round(duration / dt))
    q = np.asarray(q0, dtype=float).copy()
    v = np.asarray(v0, dtype=float).copy()
    theta_hat = np.zeros(n_theta) if loop.theta_hat0 is None else np.asarray(loop.theta_hat0, float).copy()
    observer = ctrl.observer
    obs = observer.initial_state(q) if observer else np.zeros(0)   # v̂(0) = 0: the true q̇(0) is not measured
    arbiter = ArbiterState(machine_latched=loop.sharing.mode is Mode.MACHINE,
                           k_h=0.0 if loop.sharing.mode is Mode.MACHINE else 1.0)
    law: MachineLaw | None = None
    law_state = np.zeros(0)
    engaged_before = False
    rec = _Recorder(steps, n, n_theta, optional=("true_class", "own_law", "wish_inside"))
    finite = True
    is_omni = hasattr(model, "wheel_torques")

    def velocity_for_control(q_, v_, obs_):
        return observer.velocity(q_, obs_) if observer else v_


    zero_n, zero_theta = np.zeros(n), np.zeros(n_theta)
    no_law_rate = {}
    backup = loop.backup
    # under output feedback the backup-safe checks judge every velocity within the observer's error of v̂
    observed = backup.observer_error if backup is not None and observer and backup.observer_error else None

    def class_rows(q_, v_, u_h, slack=None):
        """Definition 2's rows, seen through the fail-safe stop with the operator's command held,
        when the loop has a backup model; `slack`: v_ is the observer's v̂, known to within it."""
        if backup is None:
            return None
        held = model.acceleration(q_, v_, u_h) if loop.sharing.mode is not Mode.MACHINE else None
        return speed_aware_rows(backup, feasible, feasible.row_values(q_, v_), v_, loop.sharing.bands.b2, held,
                                slack)

    # the governor's λ of the current step (`rates` with want_signals finds it; the last one found starts
    # the next search, as in the sampled loop: backup._root)
    held_share = [0.0]

    def rates(t, q_, v_, th_, s_, o_, decision, want_signals=False):
        desired = human.desired(t)
        v_meas = velocity_for_control(q_, v_, o_)
        u_h = zero_n
        if loop.sharing.mode is not Mode.MACHINE and (want_signals or decision.authority is not Authority.MACHINE):
            u_h = human.command_from(t, desired, q_, v_).force
        u_f = zero_n
        th_dot = zero_theta
        s_dot = no_law_rate.get(s_.size)
        if s_dot is None:
            s_dot = no_law_rate[s_.size] = np.zeros(s_.size)
        engaged = decision.authority is not Authority.HUMAN and decision.group is not None
        if engaged:
            grp = feasible.groups[decision.group]
            c = coordinates(grp, q_, v_meas, desired, loop.reference)
            if not c.inside:
                raise _Escaped(q_, v_)
            out = law.evaluate(model, grp, c, q_, v_meas, th_, s_)
            u_f, s_dot = out.u, out.state_dot
            if decision.authority is Authority.MACHINE:
                th_dot = out.theta_dot
        u_s = shared_input(decision, u_h, u_f)
        if backup is not None and decision.authority is not Authority.HUMAN:
            # the governor is part of the step's decision: its share λ is found at the step's start and
            # held over the stages (the fallback u_g at each stage's own state), as the sampled loop
            # holds one governed command per period
            if want_signals:
                held_share[0] = govern(backup, model, feasible, q_, v_meas, u_s, dt, observed,
                                       hint=held_share[0]).share
            share = held_share[0]
            if share > 0.0:
                u_g = model.inverse_dynamics(q_, v_meas, backup.fallback_acceleration(v_meas))
                u_s, th_dot = u_s + share * (u_g - u_s), zero_theta   # the law's update assumes u_f acts; it did not
        if engaged:
            s_dot = law.with_applied_input(s_dot, u_s)
        acc = model.acceleration(q_, v_, u_s)
        o_dot = observer.derivative(q_, o_) if observer else o_
        derivs = (v_, acc, th_dot, s_dot, o_dot)
        if want_signals:
            return derivs, (u_h, u_f, u_s, v_meas, desired)
        return derivs

    k = 0
    for k in range(steps):
        t = k * dt
        desired = human.desired(t)
        v_meas = velocity_for_control(q, v, obs)
        command = human.command_from(t, desired, q, v)
        intent = 0.0 if loop.sharing.mode is Mode.MACHINE else command.intent
        q_r_all, values = all_groups(feasible.stack, q, v_meas, desired, loop.reference, ctrl.tracking.lam)
        ref_ok = feasible.reference_inside(q_r_all)
        wish_inside = wish_admissible(feasible, desired.q, loop.reference.epsilon)
        seen = class_rows(q, v_meas, command.force, observed)
        pushes = operator_pushes(feasible, command.force)
        push_away = wish_inside and push_turned_away(feasible, q, desired.q, command.force, loop.reference.epsilon,
                                                     loop.sharing.bands, None if seen is None else seen[0], pushes)
        arbiter, decision = arbitrate(feasible, loop.sharing, arbiter, q, v_meas, intent, dt,
                                      values.__getitem__, ref_ok, seen, push_away=push_away, pushes=pushes,
                                      push_power=float(np.dot(v_meas, command.force)))
        engaged = decision.authority is not Authority.HUMAN and decision.group is not None
        if engaged and (not engaged_before or decision.group_changed or ctrl.law(decision.role) is not law):
            if law is not None and law_state.size:
                theta_hat = law.estimate(theta_hat, law_state)
            law = ctrl.law(decision.role)
            grp = feasible.groups[decision.group]
            c = coordinates(grp, q, v_meas, desired, loop.reference)
            law_state = law.initial_state(model, grp, c, q, v_meas, theta_hat)
        elif not engaged and engaged_before and law is not None and law_state.size:
            theta_hat = law.estimate(theta_hat, law_state)
            law_state = np.zeros(0)
        engaged_before = engaged

        try:
            (d1, signals) = rates(t, q, v, theta_hat, law_state, obs, decision, want_signals=True)
        except _Escaped:
            rec.put(k, t=t, q=q, v=v, margin=feasible.margin(q), inside=feasible.contains(q))
            k += 1
            break
        u_h, u_f, u_s, v_meas, desired = signals
        ref_group = (decision.group if engaged
                     else select_group(feasible, decision.situation, values.__getitem__, ref_ok))
        q_r = q_r_all[ref_group] if ref_group is not None else np.full(n, np.nan)
        estimate = law.estimate(theta_hat, law_state) if (law is not None and law_state.size) else theta_hat
        rec.put(
            k, t=t, q=q, v=v, v_hat=v_meas, q_d=desired.q, q_r=q_r, u_h=u_h, u_f=u_f, u_s=u_s,
            tau=model.wheel_torques(q, u_s) if is_omni else u_s,
            theta_hat=estimate, authority=int(decision.authority), set_class=int(decision.situation.overall),
            group=-1 if decision.group is None else decision.group, role=int(decision.role),
            k_h=decision.k_h, k_f=decision.k_f, intent=intent, margin=feasible.margin(q),
            inside=feasible.contains(q),
            true_class=int(decision.situation.overall if observer is None
                           else classify(feasible, q, v, loop.sharing.bands, class_rows(q, v, command.force)).overall),
            own_law=engaged and ctrl.owns(law), wish_inside=wish_inside,
        )

        state = (q, v, theta_hat, law_state, obs)
        try:
            q, v, theta_hat, law_state, obs = _advance(rates, decision, t, state, dt, d1)
        except _Escaped as escape:
            # an integration stage left the active group's polytope: the law has no value
            # there (z = ln(x/x_r) needs x < 0). Record that state as the last sample.
            if k + 1 < steps:
                rec.put(k + 1, t=t + dt, q=escape.q, v=escape.v, margin=feasible.margin(escape.q),
                        inside=feasible.contains(escape.q))
                k += 1
            k += 1
            break
        if law is not None:
            theta_hat = law.project(model, theta_hat)       # onto the physical box, when the law projects
        if not all(np.all(np.isfinite(x)) for x in (q, v, theta_hat, law_state, obs)):
            finite = False
            k += 1
            break
    else:
        k = steps
    return rec.trace(k, finite, arbiter.switches, arbiter.group_switches, theta=model.theta)


class _Escaped(Exception):
    def __init__(self, q, v):
        super().__init__("state left the active group")
        self.q, self.v = q, v


def _axpy(state, rate, h):
    return tuple(s + h * r for s, r in zip(state, rate))


#: h·ρ̂ above which a step is checked against two half steps: RK4's stability region holds the
#: half-disc |hλ| ≤ 2 of the left half-plane (it reaches −2.785 on the real axis, ±2.83i on the imaginary)
STIFF_STEP = 2.0
#: a checked step is kept while it differs from its two half steps by at most this share of their change
STEP_AGREEMENT = 0.5
#: the shortest step is dt/2^MAX_HALVINGS; below it a step is kept unchecked
MAX_HALVINGS = 10


def _squared_distance(a, b) -> float:
    return sum(float(np.dot(x - y, x - y)) for x, y in zip(a, b))


def _rk4(rates, decision, t, state, h, d1):
    """One classical RK4 step from `state` (rate d1 there) and h·ρ̂, the step's estimate of h times
    the largest |eigenvalue| of the closed loop's Jacobian: d2 and d3 are rates at the same instant
    t + h/2 at states (h/2)(d2 − d1) apart, so h·ρ̂ = 2|d3 − d2| / |d2 − d1| (one power iteration;
    Hairer and Wanner's stiffness detection for explicit Runge–Kutta methods; hλ for f(y) = λy)."""
    d2 = rates(t + h / 2, *_axpy(state, d1, h / 2), decision)
    d3 = rates(t + h / 2, *_axpy(state, d2, h / 2), decision)
    d4 = rates(t + h, *_axpy(state, d3, h), decision)
    end = tuple(s + (h / 6.0) * (a + 2.0 * b + 2.0 * c + d) for s, a, b, c, d in zip(state, d1, d2, d3, d4))
    spread = _squared_distance(d2, d1)
    return end, (2.0 * (_squared_distance(d3, d2) / spread) ** 0.5 if spread > 0.0 else 0.0)


def _advance(rates, decision, t, state, h, d1, halvings=0):
    """The continuous state after h with `decision` held: one RK4 step, or two half steps where one
    is too long for the loop's stiffness (each refined the same way, down to dt/2^MAX_HALVINGS).

    Near a face the laws' feedforward Y θ̂ holds M̂ v̇_ref, whose gain on q̇ grows like
    M⁻¹M̂ (1 + λ_q)/|x|. θ̂ moves within Theorem 1's bound, not towards θ, and an estimated inertia
    far from the true one (indefinite, or far above it in the direction of M's small eigenvalue) gives
    the loop a mode faster than a fixed step can follow: an RK4 step past its stability bound
    amplifies what the law damps, L grows where it must fall, and the simulated run leaves the set
    while the loop it stands for does not. So a step whose h·ρ̂ (`_rk4`) exceeds STIFF_STEP is
    compared with two half steps and kept when it differs from them by at most STEP_AGREEMENT of
    their change. For a linear decaying mode that share is ½ at hλ ≈ −2.4 and 1 at RK4's bound
    −2.785, so no step that amplifies a mode is kept; where ρ̂ is set off by a rate that is not
    smooth over the step (an observer's switch) the step is accurate and the share
    small (below 0.1 on the packaged scenarios and the property tests' cases). A kept step is the
    plain RK4 step: the check changes nothing where the step is stable. A stage that leaves the
    active group raises _Escaped, refined or not."""
    end, h_rho = _rk4(rates, decision, t, state, h, d1)
    if h_rho <= STIFF_STEP or halvings >= MAX_HALVINGS:
        return end
    mid, _ = _rk4(rates, decision, t, state, h / 2, d1)
    halves, _ = _rk4(rates, decision, t + h / 2, mid, h / 2, rates(t + h / 2, *mid, decision))
    if _squared_distance(end, halves) <= STEP_AGREEMENT**2 * _squared_distance(halves, state):
        return end
    mid = _advance(rates, decision, t, state, h / 2, d1, halvings + 1)
    return _advance(rates, decision, t + h / 2, mid, h / 2, rates(t + h / 2, *mid, decision), halvings + 1)
