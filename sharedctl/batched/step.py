"""One step of simulator.simulate for every robot of a batch.

1. the sharing function is sampled at the start of the step (arbiter.py) and held over it —
   with a backup model, on Definition 2's rows seen through the fail-safe stop (backup.py's
   speed_aware_rows, the operator's command held); on a take-over, group or law change the
   incoming law's filters restart from their published initial conditions ((15), (26), (28))
   and θ̂ carries over (θ̂ + β when leaving (13));
2. one classical RK4 step of the state [q, q̇, θ̂, law state, observer], the law evaluated at
   every stage on each robot's own group, and u_s, unless the operator has authority, made
   backup-safe by the governor (backup.py's govern, its share λ found at the step's start and
   held over the stages; where it moves u_s, θ̂ holds for the step); θ̂ moves only under full
   machine authority (its rate ends with the robust update's leakage), and is projected onto the
   last law's physical box B after the step when it projects;
3. a robot whose RK stage leaves its active group's polytope (the law has no value there), or
   whose state turns non-finite, stops, with the rows simulator.simulate records for it.

The arithmetic of each formula is the scalar simulator's, operation for operation, so the
batch reproduces it to rounding (docs/performance.md, "Batched simulator", states the tolerance).
"""
from __future__ import annotations

import numpy as np

from ..sharing import Mode
from .arbiter import HUMAN, MACHINE, arbitrate
from .geometry import (
    GroupsOnDemand, RowValues, all_groups, classify, missed_rows, projected_configuration, reference_inside,
    row_reference, push_turned_away, wish_admissible, select_group,
)
from .laws import GroupFrame, coordinates, gather, projected_reference, scatter
from .plant import acceleration, regressor_times
from .results import Rows


class StepKernel:
    """The per-step computation; `engine` carries the scenario's tables, laws and constants."""

    def __init__(self, engine):
        self.e = engine
        self._reference = (None, None, None, None)
        self._moved, self._share = np.zeros(0, dtype=np.intp), np.zeros(0)   # the governor's λ of this step (`govern`)

    def reference(self, wish):
        """(RowReference, reference_inside, wish_admissible) of `wish`; a wish that is the same object as
        the last step's (a point wish, operators.py) keeps its values."""
        last, row_ref, ref_ok, wish_ok = self._reference
        if wish is not last:
            table = self.e.table
            row_ref = row_reference(table, wish.q, wish.q_dot, self.e.shape)
            ref_ok = reference_inside(table, row_ref.shifted)
            wish_ok = wish_admissible(table, wish.q, self.e.shape.epsilon)
            self._reference = (wish, row_ref, ref_ok, wish_ok)
        return row_ref, ref_ok, wish_ok

    def step(self, fleet, k: int, steps: int, recording):
        """Advance `fleet` by one step; returns (stopping columns, their Trace.finite) or None."""
        e = self.e
        L, dt = e.layout, e.dt
        Y, ops = fleet.Y, fleet.operators
        N = fleet.size
        t = k * dt
        h = dt / 2
        q, v, theta_hat, law_state = Y[L.q], Y[L.v], Y[L.theta], Y[L.law_state]
        wishes = (ops.desired(t), ops.desired(t + h), ops.desired(t + dt))
        wish = wishes[0]
        v_meas = e.observer.velocity(q, Y[L.obs]) if e.observer else v
        if e.mode is Mode.MACHINE:
            u_h0, intent = np.zeros_like(q), np.zeros(N)
        else:
            u_h0, intent = ops.command(wish, q, v)
        groups, situation, chosen, dec = self.decide(fleet, q, v_meas, wish, u_h0, intent, dt)
        engaged = (dec.authority != HUMAN) & (dec.group >= 0)
        self.engage(fleet, dec, engaged, groups, theta_hat, law_state)

        # --- RK4 -----------------------------------------------------------------------------
        plan = self.plan(engaged, dec, wishes)
        machine = dec.authority == MACHINE
        escaped = np.zeros(N, bool)
        d1, u_h, u_f, u_s = self.rates(fleet, Y, wish, plan, 0, dec, machine, escaped, u_h0, record=True)
        stage1 = escaped.copy()
        rows = self.rows(t, fleet, Y, v_meas, wish, groups, chosen, engaged, dec, situation, intent,
                         (u_h, u_f, u_s), stage1, u_h0)
        fleet.tally.add(rows)
        if recording is not None:
            recording.put(k, fleet.ids, rows)

        stage = np.multiply(d1, h)
        stage += Y
        d2 = self.rates(fleet, stage, wishes[1], plan, 1, dec, machine, escaped)[0]
        first_escape = {}
        _note(first_escape, escaped, stage1, stage)
        np.multiply(d2, h, out=stage)
        stage += Y
        d3 = self.rates(fleet, stage, wishes[1], plan, 1, dec, machine, escaped)[0]
        _note(first_escape, escaped, stage1, stage)
        np.multiply(d3, dt, out=stage)
        stage += Y
        d4 = self.rates(fleet, stage, wishes[2], plan, 2, dec, machine, escaped)[0]
        _note(first_escape, escaped, stage1, stage)
        # s + (dt/6)(a + 2b + 2c + d), summed in that order
        nxt = np.multiply(d2, 2.0, out=stage)
        nxt += d1
        d3 *= 2.0
        nxt += d3
        nxt += d4
        nxt *= dt / 6.0
        nxt += Y
        projecting = (fleet.law_role >= 0) & e.projects[fleet.law_role]
        if projecting.any():
            th = nxt[L.theta]
            for index, law in enumerate(e.distinct):         # onto each law's physical box B (RobustUpdate)
                cols = np.flatnonzero(projecting & e.runs(index, fleet.law_role))
                if cols.size:
                    sel = None if cols.size == N else cols
                    scatter(th, sel, law.project(gather(th, sel)))
        finite = np.isfinite(nxt).all(axis=0)
        going = ~escaped & finite
        fleet.Y = nxt
        if going.all():
            return None

        # --- robots that stop this step ---------------------------------------------------------
        late = escaped & ~stage1
        if late.any() and k + 1 < steps:
            cols = np.flatnonzero(late)
            Ye = np.stack([first_escape[c] for c in cols], axis=1)
            extra = self.escape_rows(t + dt, Ye[L.q], Ye[L.v])
            fleet.tally.add(extra, cols)
            if recording is not None:
                recording.put(k + 1, fleet.ids[cols], extra)
        stop = np.flatnonzero(~going)
        return stop, finite[stop] | escaped[stop]

    def decide(self, fleet, q, v_meas, wish, u_h0, intent, dt, on_demand: bool = False):
        """The sharing function sampled at (q, v_meas): (AllGroups, Situation, chosen group, Decisions);
        fleet.arbiter moves on by dt. `on_demand`: every group's p and selection value only for the
        robots whose group the arbiter chooses anew (geometry.GroupsOnDemand; the chosen group is then
        None): what the sampled controller needs, not the simulator's record of q_r."""
        e = self.e
        table = e.table
        row_ref, ref_ok, wish_ok = self.reference(wish)
        if on_demand:
            groups = GroupsOnDemand(table, q, v_meas, row_ref, e.lam)
        else:
            groups = all_groups(table, q, v_meas, row_ref, e.lam)
        seen = self.seen_rows(fleet, groups.rows.x, v_meas, u_h0, self.observed())
        situation = classify(table, groups.rows, e.sharing.bands, seen)
        missed = missed_rows(table, situation)
        if on_demand:
            def chosen(want):
                out = np.full(want.size, -1)
                cols = np.flatnonzero(want)
                if cols.size:
                    _, value = groups.values(cols)
                    out[cols] = select_group(table, situation.take(cols), value, missed[:, cols], ref_ok[:, cols])
                return out
        else:
            chosen = select_group(table, situation, groups.value, missed, ref_ok)
        pushes = table.row_K @ u_h0
        push_away = push_turned_away(table, seen, pushes, wish_ok, situation.containing, e.sharing.bands)
        fleet.arbiter, dec = arbitrate(table, e.sharing, fleet.arbiter, situation, seen, missed, chosen,
                                       intent, dt, push_away, pushes, groups.rows.x, np.sum(v_meas * u_h0, axis=0))
        return groups, situation, None if on_demand else chosen, dec

    def engage(self, fleet, dec, engaged, groups, theta_hat, law_state) -> None:
        """Law (re)initialisation, as in simulator.simulate: on a take-over, group or law change the
        incoming law's filters restart from their published initial conditions and θ̂ carries over
        (θ̂ + β when leaving (13)); a release hands the estimate back to θ̂. In place on the fleet."""
        e, table = self.e, self.e.table
        law_changed = (fleet.law_role < 0) | (e.law_of_role[dec.role] != e.law_of_role[np.maximum(fleet.law_role, 0)])
        reinit = engaged & (~fleet.engaged_before | dec.group_changed | law_changed)
        release = ~engaged & fleet.engaged_before & fleet.has_state
        carry = (reinit | release) & fleet.has_state
        if carry.any():
            for index, law in enumerate(e.distinct):
                cols = np.flatnonzero(carry & e.runs(index, fleet.law_role))
                if cols.size:
                    theta_hat[:, cols] = law.estimate(theta_hat[:, cols], law_state[: law.state_size, cols])
        if reinit.any():
            cols = np.flatnonzero(reinit)
            roles = dec.role[cols]
            for index, law in enumerate(e.distinct):
                sub = cols[e.runs(index, roles)]
                if sub.size and law.state_size:
                    g = dec.group[sub]
                    z = groups.rows.z[table.group_rows[g], sub[:, None]].T
                    law_state[: law.state_size, sub] = law.initial_state(z, groups.p_of(g, sub))
            fleet.law_role[cols] = roles
            fleet.has_state[cols] = e.state_size[roles] > 0
        fleet.has_state &= ~release
        fleet.engaged_before = engaged

    # ------------------------------------------------------------------------------
    def plan(self, engaged, dec, wishes):
        """Per distinct law: its robots (None for every robot of the chunk), their group frames
        and the projected reference at the three stage times t, t + dt/2, t + dt (the reference
        depends on the wish only; identical wishes share one)."""
        e = self.e
        cols_all = np.flatnonzero(engaged)
        if cols_all.size == 0:
            return []
        N = engaged.size
        entries = []
        roles = dec.role[cols_all]
        for index, law in enumerate(e.distinct):
            cols = cols_all[e.runs(index, roles)]
            if cols.size == 0:
                continue
            sel = None if cols.size == N else cols
            frame = GroupFrame.of(e.table.K_cols, e.table.T_cols, e.table.K_inv_cols, dec.group[cols])
            refs = []
            for i, w in enumerate(wishes):
                same = next((refs[j] for j in range(i) if wishes[j] is w), None)
                if same is None:
                    same = projected_reference(frame, gather(w.q, sel), gather(w.q_dot, sel), gather(w.q_ddot, sel),
                                               e.shape)
                refs.append(same)
            entries.append((law, cols, sel, frame, refs))
        return entries

    def rates(self, fleet, Y, wish, plan, stage_time, dec, machine, escaped, u_h=None, record=False, u_extra=None):
        """The closed loop's rate at one RK stage (simulator.simulate's `rates`); with `record`,
        also u_h, u_f and u_s. `u_extra` (n, N), if given, is added to u_s before the governor (the
        sampled controller's recovery force, sampled.py)."""
        e = self.e
        L, n = e.layout, e.n
        q, v, theta_hat, law_state = Y[L.q], Y[L.v], Y[L.theta], Y[L.law_state]
        N = Y.shape[1]
        out = np.empty_like(Y)
        out[L.q] = v
        out[L.theta] = 0.0
        out[L.law_state] = 0.0
        obs = Y[L.obs] if e.observer else None
        v_meas = e.observer.velocity(q, obs) if e.observer else v
        if u_h is None:
            u_h = np.zeros((n, N)) if e.mode is Mode.MACHINE else fleet.operators.force(wish, q, v)
        # (46)/(47): u_s = w_h u_h + w_f u_f, u_f = 0 where no law is engaged
        u_s = np.multiply(dec.human_weight, u_h)
        u_f = np.zeros((n, N)) if record else None
        for law, cols, sel, frame, refs in plan:
            c = coordinates(frame, gather(q, sel), refs[stage_time])
            if sel is None:
                escaped |= ~c.inside
            else:
                escaped[cols] |= ~c.inside
            size = law.state_size
            u, theta_dot, rate = law.evaluate(frame, c, gather(v_meas, sel), gather(theta_hat, sel),
                                              gather(law_state[:size], sel))
            if record:
                scatter(u_f, sel, u)
            u *= gather(dec.machine_weight, sel)
            u += gather(u_s, sel)
            scatter(u_s, sel, u)
            if size:
                scatter(out[L.law_state.start: L.law_state.start + size], sel, rate)
            mach = gather(machine, sel)
            if mach.all():
                scatter(out[L.theta], sel, theta_dot)
            elif mach.any():
                scatter(out[L.theta], sel, np.where(mach, theta_dot, 0.0))
        if u_extra is not None:
            u_s += u_extra
        if e.backup is not None:
            self.govern(fleet, q, v_meas, u_s, dec, out[L.theta], record)
        for law, _, sel, _, _ in plan:
            if law.applied_input is not None:                   # a filter of u_s (with_applied_input)
                rows = slice(L.law_state.start + law.applied_input.start, L.law_state.start + law.applied_input.stop)
                scatter(out[rows], sel, gather(out[rows], sel) + gather(u_s, sel))
        acceleration(fleet.theta, v, u_s, out[L.v])
        if e.observer:
            e.observer.derivative(q, obs, out[L.obs])
        return out, u_h, u_f, u_s

    def estimate(self, fleet, theta_hat, law_state):
        """The estimate each robot's law stands for (θ̂, or θ̂ + β under (13))."""
        e = self.e
        estimate = theta_hat.copy()
        for index, law in enumerate(e.distinct):
            if law.state_size:
                cols = np.flatnonzero(fleet.has_state & e.runs(index, fleet.law_role))
                if cols.size:
                    estimate[:, cols] = law.estimate(theta_hat[:, cols], law_state[: law.state_size, cols])
        return estimate

    def rows(self, t, fleet, Y, v_meas, wish, groups, chosen, engaged, dec, situation, intent, signals, escaped,
             u_h0):
        """The simulator's recorded sample at the start of the step (partial where the first stage escaped)."""
        L = self.e.layout
        u_h, u_f, u_s = signals
        ref_group = np.where(engaged, dec.group, chosen)
        q_r = projected_configuration(self.e.table, groups.rows.shifted_reference, ref_group)
        estimate = self.estimate(fleet, Y[L.theta], Y[L.law_state])
        extra = {"v_hat": v_meas, "q_d": wish.q, "u_h": u_h, "u_f": u_f, "set_class": dec.overall, "group": dec.group,
                 "role": dec.role, "k_h": dec.k_h, "k_f": dec.k_f, "intent": intent,
                 "true_class": self.true_class(fleet, Y, groups, situation, u_h0),
                 "own_law": engaged & self.e.owns(dec.role)}             # MachineController.owns
        rows = Rows(t, Y[L.q], Y[L.v], q_r, u_s, estimate, dec.authority, situation.margin, situation.inside, extra)
        if escaped.any():
            # simulator.simulate records only t, q, v, margin and inside when the first stage escapes
            for name in ("q_r", "u_s", "theta_hat"):
                arr = np.array(getattr(rows, name), dtype=float)
                arr[:, escaped] = np.nan
                setattr(rows, name, arr)
            rows.authority = np.where(escaped, -1, rows.authority)
            for name, value in extra.items():
                if name == "own_law":
                    extra[name] = value & ~escaped
                    continue
                labels = name in ("set_class", "group", "role", "true_class")
                value = np.array(value, dtype=int if labels else float)
                value[..., escaped] = -1 if labels else np.nan
                extra[name] = value
        return rows

    def true_class(self, fleet, Y, groups, situation, u_h0):
        """Definition 2's class of the true state (q, q̇): the arbiter's, unless it sees the observer's v̂
        (then the rows of the true q̇, through the stop with the operator's command held)."""
        if not self.e.observer:
            return situation.overall
        rows, L = groups.rows, self.e.layout
        v = Y[L.v]
        true_rows = RowValues(rows.x, self.e.table.row_K @ v, rows.z, rows.shifted_reference)
        seen = self.seen_rows(fleet, rows.x, v, u_h0)
        return classify(self.e.table, true_rows, self.e.sharing.bands, seen).overall

    def seen_rows(self, fleet, x, v, u_h, slack=None):
        """The row values x (P, N) the sharing function classifies (simulator.simulate's `class_rows`):
        x itself without a backup model, else seen through the fail-safe stop from velocity v with the
        operator's u_h held (backup.speed_aware_rows; the state's own stop in machine mode); `slack`: v is
        the observer's v̂, known to within it."""
        e = self.e
        if e.backup is None:
            return x
        held = None if e.mode is Mode.MACHINE else acceleration(fleet.theta, v, u_h, np.empty_like(u_h))
        return e.backup.speed_aware_rows(x, v, e.sharing.bands.b2, held, slack)

    def observed(self):
        """The slack of the backup-safe checks (simulator.simulate's `observed`): under output feedback
        the backup model's observer error, else None."""
        e = self.e
        error = e.backup.model.observer_error if e.backup is not None else ()
        return error if e.observer and error else None

    def govern(self, fleet, q, v_meas, u_s, dec, theta_rate, start: bool):
        """backup.govern on u_s (n, N, in place) wherever the operator does not have authority; θ̂'s rate
        (`theta_rate`, in place) is zeroed where the governor moved u_s: the law's update assumes
        u_f acts, and it did not. As in simulator.simulate, λ is found at the step's `start` and held
        over the later stages, the fallback u_g at each stage's own state."""
        if start:
            self._moved = np.zeros(0, dtype=np.intp)
            cols = np.flatnonzero(dec.authority != HUMAN)
            if cols.size == 0:
                return
            sel = None if cols.size == u_s.shape[1] else cols
            sent, share = self.e.backup.govern(gather(fleet.theta, sel), gather(q, sel), gather(v_meas, sel),
                                               gather(u_s, sel), self.e.dt, self.observed(),
                                               gather(fleet.share, sel))
            fleet.share[slice(None) if sel is None else sel] = share     # where the next search starts
            moved = share > 0.0
            if not moved.any():
                return
            scatter(u_s, sel, sent)
            self._moved = np.flatnonzero(moved) if sel is None else cols[moved]
            self._share = share[moved]
            theta_rate[:, self._moved] = 0.0
            return
        cols = self._moved
        if cols.size == 0:
            return
        theta, qc, vc, uc = (arr.take(cols, axis=1) for arr in (fleet.theta, q, v_meas, u_s))
        u_g = regressor_times(vc, vc, self.e.backup.fallback_acceleration(vc), theta)   # model.inverse_dynamics
        u_s[:, cols] = uc + self._share * (u_g - uc)
        theta_rate[:, cols] = 0.0

    def escape_rows(self, t, q, v):
        """The row simulator.simulate records for a state an RK stage reached outside the group."""
        e = self.e
        M = q.shape[1]
        margin = np.array([e.feasible.margin(q[:, i]) for i in range(M)])
        inside = np.array([e.feasible.contains(q[:, i]) for i in range(M)])
        nan_n = np.full((e.n, M), np.nan)
        extra = {"v_hat": nan_n, "q_d": nan_n, "u_h": nan_n, "u_f": nan_n, "set_class": np.full(M, -1),
                 "group": np.full(M, -1), "role": np.full(M, -1), "k_h": np.full(M, np.nan), "k_f": np.full(M, np.nan),
                 "intent": np.full(M, np.nan), "true_class": np.full(M, -1), "own_law": np.zeros(M, bool)}
        return Rows(t, q, v, nan_n, nan_n, np.full((e.k, M), np.nan), np.full(M, -1), margin, inside, extra)


def _note(first_escape, escaped, stage1, Ys):
    """Remember the stage state at which each robot first escaped (after the first stage)."""
    if np.count_nonzero(escaped) == len(first_escape) + np.count_nonzero(stage1):
        return                                  # no new escape (the usual case)
    for c in np.flatnonzero(escaped & ~stage1):
        first_escape.setdefault(int(c), Ys[:, c].copy())
