"""The shared controller as a discrete-time step function, for processes that sample.

The simulator (simulator.py) integrates plant and controller together; a real controller
samples its measurements every period, holds its command, and advances its own states
(θ̂, the law's filters, the observer) over the period. `SharedController.step` is that: the
same sharing function (sharing.py), the same laws and the same re-initialisation policy as
the simulator, with the controller's states advanced by one forward-Euler step of the law's
own rates at the sampled (q, q̇) and the command u_s it returns (at 500 Hz the fastest
controller pole, the observer's K_a = 60 s⁻¹, gives K_a·dt = 0.12). State in, command out:
`ControllerState` is explicit and immutable, so the daemon, a test and a replay all run the
same code.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .backup import BackupModel, command_spans, govern, speed_aware_rows, uncertain_prediction
from .constraints import FeasibleSet
from .models import EulerLagrangeModel
from .reference import ReferenceShape
from .sets import SetClass
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
)
from .short_vectors import all_finite, floats
from .simulator import MachineController
from .transform import Desired, all_groups, coordinates


@dataclass(frozen=True)
class ControllerState:
    arbiter: ArbiterState
    theta_hat: np.ndarray
    law_role: LawRole | None = None      # which law's state `law_state` holds (None: none engaged)
    law_state: np.ndarray = field(default_factory=lambda: np.zeros(0))
    observer: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sent: tuple = ()       # the last commands u_s, oldest first (the predictor's input history)
    held: tuple = ()       # how long each of `sent` but the newest acted (s); the newest acts until the next step
    backup_share: float = 0.0   # the governor's last λ: where its next search starts (backup._root)


@dataclass(frozen=True)
class OperatorInput:
    """What the operator sends: the wish (q_d, q̇_d, q̈_d) and the joystick force u_h with its intent v_h."""

    desired: Desired
    force: np.ndarray
    intent: float


@dataclass(frozen=True)
class StepOutput:
    u_s: np.ndarray          # generalised force to apply until the next sample
    u_h: np.ndarray
    u_f: np.ndarray
    authority: Authority
    set_class: SetClass
    group: int | None
    role: LawRole
    k_h: float
    k_f: float
    reference: "np.ndarray | _PickedReference" = field(repr=False, compare=False)   # q_r, or how to find it
    theta_estimate: np.ndarray
    v_used: np.ndarray       # q̇ (state feedback) or the observer's v̂ (output feedback)
    region_margins: np.ndarray
    backup_share: float = 0.0          # λ of backup.govern: 0 = u_s as sharing gave it, 1 = the fallback

    @cached_property
    def q_r(self) -> np.ndarray:
        """The projected reference: the active group's, or, while the operator has authority, that of
        the group the machine would pick (NaN if none applies). The latter is worked out on first read
        (every group's projection: half an operator-only step, which the daemon needs only for its
        telemetry) from the step's own inputs."""
        return self.reference.q_r() if isinstance(self.reference, _PickedReference) else self.reference


@dataclass
class SharedController:
    """(46)/(47) with the configured machine laws, sampled every `dt` seconds."""

    model: EulerLagrangeModel
    feasible: FeasibleSet
    machine: MachineController
    sharing: SharingParameters = field(default_factory=SharingParameters)
    reference: ReferenceShape = field(default_factory=ReferenceShape)
    backup: BackupModel | None = None      # the fail-safe stop the commands are kept safe for (backup.py)

    def initial_state(self, q0: np.ndarray, theta_hat0: np.ndarray | None = None) -> ControllerState:
        machine_mode = self.sharing.mode is Mode.MACHINE
        arbiter = ArbiterState(machine_latched=machine_mode, k_h=0.0 if machine_mode else 1.0)
        theta = np.zeros(self.model.n_theta) if theta_hat0 is None else np.asarray(theta_hat0, float)
        observer = self.machine.observer.initial_state(np.asarray(q0, float)) if self.machine.observer else np.zeros(0)
        return ControllerState(arbiter, theta.copy(), None, np.zeros(0), observer)

    def step(self, state: ControllerState, q: np.ndarray, v: np.ndarray | None, operator: OperatorInput, dt: float,
             delay: float = 0.0, elapsed: float | None = None):
        """One sample: returns (next state, output). `v` may be None for output feedback.

        `delay` (s): how old (q, q̇) will be when the command computed now acts — the feedback's
        age plus the command's transit, as measured. With state feedback the step then runs on the
        state predicted for that instant (`predict`: the model driven by the commands this
        controller sent meanwhile, each over the time it acted: `in_flight`), so its barrier acts
        on where the robot will be, not where it was (predictor feedback, docs/control.md §10).
        `elapsed` (s): how long the last command acted, the time since the last step (default dt;
        a sampler whose ticks come late passes the true interval, where its `dt` may be cut).

        The hot path of the daemon (docs/performance.md): per-step constants are cached where
        they are built (stacked rows, gain vectors, parameter box); the per-sample arithmetic —
        the rows of Definition 2, the active group's (6)–(11), the laws — runs on Python floats
        (short_vectors), with numpy arrays only at the interface; every group's evaluation for
        (46)'s selection is made only when a group is to be selected (_EveryGroupOnDemand), and for
        the reference reported while the operator has authority only when it is read (StepOutput.q_r).
        tests/test_shared_step_reference.py holds it to recorded outputs.
        """
        model, feasible, machine = self.model, self.feasible, self.machine
        observer = machine.observer
        acted = state.held + (dt if elapsed is None else elapsed,) if state.sent else ()
        commands, spans = in_flight(state.sent, acted, delay)
        if commands and observer is None:
            q, v = predict(model, q, v, commands, spans)
        v_used = observer.velocity(q, state.observer) if observer else np.asarray(v, float)
        mode = self.sharing.mode
        intent = 0.0 if mode is Mode.MACHINE else operator.intent
        q_list, v_list = floats(q), v_used.tolist()
        rows = feasible.row_values(q_list, v_list)
        backup = self.backup
        class_rows = rows
        if backup is not None:
            judged = judged_state(backup, model, observer, q, v_used, commands, spans)
            q_b, v_b, slack, offset = judged
            rows_b = rows if q_b is q else feasible.row_values(floats(q_b), v_b.tolist())
            held = model.acceleration(q_b, v_b, operator.force) if mode is not Mode.MACHINE else None
            class_rows = speed_aware_rows(backup, feasible, rows_b, v_b, self.sharing.bands.b2, held, slack, offset)
        every_group = _EveryGroupOnDemand(feasible, np.array(q_list), np.array(v_list), operator.desired,
                                          self.reference, machine.tracking.lam)
        pushes = operator_pushes(feasible, operator.force)
        arbiter, decision = arbitrate(feasible, self.sharing, state.arbiter, q, v_used, intent, dt,
                                      every_group.lyapunov, every_group, class_rows,
                                      push_turned_away(feasible, q_list, operator.desired.q, operator.force,
                                                       self.reference.epsilon, self.sharing.bands, class_rows[0],
                                                       pushes), pushes, float(np.dot(v_used, operator.force)))

        theta_hat, law_role, law_state = state.theta_hat, state.law_role, state.law_state
        engaged = decision.authority is not Authority.HUMAN and decision.group is not None
        if engaged:
            grp = feasible.groups[decision.group]
            c = coordinates(grp, q_list, v_list, operator.desired, self.reference,
                            feasible.group_rows(decision.group, rows))
        previous_law = machine.law(law_role) if law_role is not None else None
        incoming = machine.law(decision.role)
        # outside the active group (possible only sampled, with delay) no law has a value: the recovery force
        # acts, and the law is disengaged, so the first sample back inside restarts its filters from their
        # published initial conditions instead of resuming them where they stood still
        lawful = engaged and c.inside
        if lawful and (previous_law is None or decision.group_changed or incoming is not previous_law):
            if previous_law is not None:
                theta_hat = previous_law.estimate(theta_hat, law_state)
            law_role = decision.role
            law_state = incoming.initial_state(model, grp, c, q, v_used, theta_hat)
        elif lawful:
            law_role = decision.role        # the same law in the other role: its filters carry on
        elif previous_law is not None:
            theta_hat = previous_law.estimate(theta_hat, law_state)
            law_role, law_state = None, _EMPTY

        u_h = self._zero_force() if mode is Mode.MACHINE else np.asarray(operator.force, float)
        u_f = self._zero_force()
        theta_next, law_next = theta_hat, law_state
        out = None
        if engaged:
            if lawful:
                law = machine.law(law_role)
                out = law.evaluate(model, grp, c, q, v_used, theta_hat, law_state)
                u_f = out.u
                if decision.authority is Authority.MACHINE:
                    theta_next = law.project(model, theta_hat + dt * out.theta_dot)   # B, when the law projects
            else:
                u_f = self.recovery_force(grp, q, v_used)
        u_s = shared_input(decision, u_h, u_f)
        backup_share = 0.0
        last_share = state.backup_share
        if backup is not None and decision.authority is not Authority.HUMAN:
            q_b, v_b, slack, offset = judged
            governed = govern(backup, model, feasible, q_b, v_b, u_s, dt, slack, offset, hint=last_share)
            u_s, backup_share = governed.u, governed.share
            last_share = backup_share
            if backup_share > 0.0:
                theta_next = theta_hat      # the law's update assumes u_f acts; it did not
        if out is not None and law_state.size:
            law_next = law_state + dt * law.with_applied_input(out.state_dot, u_s)   # filters see the applied u_s

        observer_next = state.observer + dt * observer.derivative(q, state.observer) if observer else state.observer
        reference = np.array(c.floats.q_r) if engaged else _PickedReference(feasible, decision.situation, every_group)
        estimate = machine.law(law_role).estimate(theta_next, law_next) if law_role is not None else theta_next
        output = StepOutput(
            u_s=u_s, u_h=u_h, u_f=u_f, authority=decision.authority, set_class=decision.situation.overall,
            group=decision.group, role=decision.role, k_h=decision.k_h, k_f=decision.k_f, reference=reference,
            theta_estimate=estimate, v_used=v_used, region_margins=feasible.region_margins(q, rows[0]),
            backup_share=backup_share,
        )
        sent = (state.sent + (u_s,))[-HISTORY:]
        acted = acted[len(acted) + 1 - len(sent):] if len(sent) > 1 else ()
        next_state = ControllerState(arbiter, theta_next, law_role, law_next, observer_next, sent,   # every field
                                     acted, last_share)
        if not (all_finite(u_s.tolist()) and all_finite(theta_next.tolist()) and all_finite(law_next.tolist())):
            raise NonFiniteCommand("the shared controller produced a non-finite value")
        return next_state, output

    def _zero_force(self) -> np.ndarray:
        return np.zeros(self.model.n)

    recovery_damping: float = 40.0      # N s/m
    recovery_stiffness: float = 400.0   # N/m

    def recovery_force(self, group, q, v) -> np.ndarray:
        """Outside the active group (possible only in sampled, delayed operation) the laws have
        no value (z = ln(x/x_r) needs x < 0): brake, and push back along the faces crossed."""
        excess = np.maximum(group.values(q) + self.reference.epsilon, 0.0)
        return -self.recovery_damping * v - self.recovery_stiffness * (group.K.T @ excess)


#: commands kept for the predictor: 64 periods (128 ms at 500 Hz) — more than any delay inside the envelope
HISTORY = 64


def in_flight(sent: tuple, held: tuple, delay: float) -> tuple[tuple, tuple]:
    """(commands, spans): what acted over the last `delay` seconds, oldest first, each with how long it
    acted within them. `sent`: the commands, oldest first; `held`: how long each acted (the newest up to
    now). Walking back from the newest, each command counts for its own time, the oldest one reached
    for what is left of the delay — so a late tick (a command held longer than a period) weighs what
    it held, where a count of commands times one period would replay the last few over the whole delay
    (a brake started a few periods ago taken for one started a delay ago). Delays shorter than 1 µs
    and remainders below it are not predicted over; with every command held one period dt and a delay
    of k·dt this is the last k commands, each held dt."""
    if not (delay > _NEGLIGIBLE) or not sent:
        return (), ()
    commands, spans, left = [], [], delay
    for u, span in zip(reversed(sent), reversed(held)):
        if left <= _NEGLIGIBLE:
            break
        part = span if span < left + _NEGLIGIBLE else left
        commands.append(u)
        spans.append(part)
        left -= part
    return tuple(reversed(commands)), tuple(reversed(spans))


#: a time below which a delay or a remainder of one is not predicted over (s)
_NEGLIGIBLE = 1e-6


def judged_state(backup: BackupModel, model, observer, q, v, commands, dt):
    """The state the backup-safe checks judge, (q, v, slack, offset): with state feedback (q, v) itself
    (`step` has predicted it already); under output feedback with `backup.observer_error`, every state
    within the observer's error of (q, v̂), predicted over the delay by the commands sent meanwhile
    (backup.uncertain_prediction; docs/control.md §10)."""
    if observer is None or not backup.observer_error:
        return q, v, None, None
    if not commands:
        return q, v, backup.observer_error, None
    return uncertain_prediction(backup, model, q, v, backup.observer_error, commands, dt)


def predict(model, q, v, commands, dt):
    """(q, q̇) after the commands (oldest first), each held dt (a period, or one per command: `in_flight`'s
    spans): per period the model's acceleration
    at its start, held (q += q̇ dt + ½a dt², q̇ += a dt) — one evaluation per period, so that a
    15 ms delay costs a few tens of µs. The plant's friction, its true parameters and this
    first-order step differ from the truth; the error over a delay L grows like L² times the force
    error over the mass, a margin docs/control.md §10 sizes."""
    q, v = np.asarray(q, float), np.asarray(v, float)
    for u, h in zip(commands, command_spans(dt, len(commands))):
        a = model.acceleration(q, v, u)
        q = q + h * v + (0.5 * h * h) * a
        v = v + h * a
    return q, v


_EMPTY = np.zeros(0)
_EMPTY.flags.writeable = False


class _EveryGroupOnDemand:
    """Every group's projected reference and selection value (transform.all_groups) and whether
    each reference lies inside its polytope (FeasibleSet.point_inside_group_region), evaluated the
    first time select_group asks: a sample in which the machine keeps its group never does.
    `lyapunov(g)` and `self[g]` are what select_group takes as `lyapunov` and `reference`."""

    def __init__(self, feasible: FeasibleSet, q, v, desired: Desired, shape: ReferenceShape, lam: float):
        self._feasible, self._args = feasible, (feasible.stack, q, v, desired, shape, lam)
        self._values = None

    def _evaluate(self):
        self.q_r, values = all_groups(*self._args)
        self._values, self._q_r_floats = values.tolist(), self.q_r.tolist()

    def lyapunov(self, g: int) -> float:
        if self._values is None:
            self._evaluate()
        return self._values[g]

    def __getitem__(self, g: int) -> bool:
        if self._values is None:
            self._evaluate()
        return self._feasible.point_inside_group_region(g, self._q_r_floats[g])


@dataclass(frozen=True)
class _PickedReference:
    """The projected reference of the group select_group would pick in this sample (StepOutput.q_r)."""

    feasible: FeasibleSet
    situation: object
    every_group: _EveryGroupOnDemand

    def q_r(self) -> np.ndarray:
        g = select_group(self.feasible, self.situation, self.every_group.lyapunov, self.every_group)
        return self.every_group.q_r[g].copy() if g is not None else np.full(self.feasible.n, np.nan)


class NonFiniteCommand(ArithmeticError):
    """Raised instead of ever returning a non-finite command; the caller stops the robot."""
