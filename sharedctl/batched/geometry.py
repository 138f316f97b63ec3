"""Constraint groups, the coordinate transform and Definition 2's sets, for a whole batch.

The vectorised forms of transform.py ((6)–(11): x, z, the projected reference (7) and the
selection value ½(|z|² + |p|²) of every group) and sets.py (Definition 2 with the inner band
b0, and its reading for unions of polytopes). Every robot shares one feasible set.

Everything elementwise in (6), (7) and Definition 2 is a function of one constraint row, and
the groups of a polytope share its rows: x, x_r, ẋ_r, z and the hazard flags are computed
once per distinct row of the feasible set (5 rows for the paper's convex set, against 12
group rows), and only what mixes rows — v_ref = K⁻¹(…), q_r, the sums over a group — per group.
Sums over a group's or a polytope's rows are products with 0/1 selection matrices.
Arrays are component-major: (rows, N).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constraints import FeasibleSet
from ..reference import ReferenceShape
from ..sets import Bands, SetClass

SAFE, HYSTERESIS, HAZARD = int(SetClass.SAFE), int(SetClass.HYSTERESIS), int(SetClass.HAZARD)


@dataclass(frozen=True)
class GroupTable:
    """The feasible set's distinct rows, its groups and its regions as index and selection arrays."""

    n: int
    K: np.ndarray              # (G, n, n) group matrices
    T: np.ndarray              # (G, n)
    K_inv: np.ndarray          # (G, n, n)
    row_K: np.ndarray          # (P, n) the distinct rows of all regions
    row_T: np.ndarray          # (P, 1)
    group_rows: np.ndarray     # (G, n) index of each group row among the distinct rows
    group_sel: np.ndarray      # (G, P) 1 where the row belongs to the group
    missed_sel: np.ndarray     # (G, P) 1 where the row belongs to the group's region but not to the group
    region_of: np.ndarray      # (G,) polytope of each group
    region_rows: tuple         # per region: indices of its rows among the distinct rows
    region_sel: np.ndarray     # (R, P) 1 where the row belongs to the region
    members: tuple             # per region: its groups' indices
    reach: np.ndarray          # (Q, P): k_j K_g⁻¹ for each group g and each row j of its region outside g,
                               # spread over the distinct rows of g (k_j q_r = reach · (x_r − t) per row)
    reach_group: np.ndarray    # (Q,) the group g of each such pair
    reach_T: np.ndarray        # (Q, 1) t_j
    reach_sel: np.ndarray      # (G, Q) 1 where the pair belongs to the group
    K_cols: np.ndarray         # (n, n, G) K with the group index last, for gathering one per robot
    T_cols: np.ndarray         # (n, G)
    K_inv_cols: np.ndarray     # (n, n, G)
    group_rows_cols: np.ndarray  # (n, G) group_rows transposed

    @staticmethod
    def of(feasible: FeasibleSet) -> "GroupTable":
        st = feasible.stack
        G, n = st.K.shape[0], st.K.shape[1]
        ids = feasible.row_ids            # the distinct rows, numbered as the scalar arbiter's held rows
        region_rows = [np.array(ids[a:b], dtype=int) for a, b in feasible.row_spans]
        P = max(ids) + 1
        row_K, row_T = np.zeros((P, n)), np.zeros((P, 1))
        stacked_K, stacked_T = feasible.row_matrix, np.concatenate([r.T for r in feasible.regions])
        for j, i in enumerate(ids):
            row_K[i], row_T[i, 0] = stacked_K[j], stacked_T[j]
        region_of = np.array([g.region for g in feasible.groups], dtype=int)
        group_rows = np.array([region_rows[g.region][list(g.rows)] for g in feasible.groups], dtype=int)
        group_sel, missed_sel = np.zeros((G, P)), np.zeros((G, P))
        for g, grp in enumerate(feasible.groups):
            group_sel[g, group_rows[g]] = 1.0
            missed_sel[g, region_rows[grp.region]] = 1.0
            missed_sel[g, group_rows[g]] = 0.0
        region_sel = np.zeros((len(region_rows), P))
        members = []
        for r, rows in enumerate(region_rows):
            region_sel[r, rows] = 1.0
            members.append(np.flatnonzero(region_of == r))
        # a group's projected reference satisfies its own rows (K_g q_r + T_g = x_r < −ε); the
        # rows of its polytope outside the group are checked through k_j q_r = (k_j K_g⁻¹)(x_r − T_g)
        pairs = [(g, j) for g, grp in enumerate(feasible.groups)
                 for j in range(feasible.regions[grp.region].K.shape[0]) if j not in grp.rows]
        reach = np.zeros((len(pairs), P))
        for q, (g, j) in enumerate(pairs):
            np.add.at(reach[q], group_rows[g], feasible.regions[feasible.groups[g].region].K[j] @ st.K_inv[g])
        reach_T = np.array([feasible.regions[feasible.groups[g].region].T[j] for g, j in pairs]).reshape(-1, 1)
        reach_group = np.array([g for g, _ in pairs], dtype=int)
        reach_sel = np.zeros((G, len(pairs)))
        reach_sel[reach_group, np.arange(len(pairs))] = 1.0
        return GroupTable(n, st.K, st.T, st.K_inv, row_K, row_T, group_rows, group_sel, missed_sel, region_of,
                          tuple(region_rows), region_sel, tuple(members), reach, reach_group, reach_T, reach_sel,
                          np.ascontiguousarray(st.K.transpose(1, 2, 0)), np.ascontiguousarray(st.T.T),
                          np.ascontiguousarray(st.K_inv.transpose(1, 2, 0)), np.ascontiguousarray(group_rows.T))

    @property
    def groups(self) -> int:
        return self.K.shape[0]

    @property
    def regions(self) -> int:
        return len(self.region_rows)


def saturate(m: np.ndarray, shape: ReferenceShape, second: bool = True):
    """x_r = σ(m), σ'(m) and (if `second`) σ''(m) of (7) (reference.saturate), elementwise.

    ln(1 + e^u) is evaluated as max(u, 0) + ln(1 + e^{−|u|}) — numpy's own logaddexp(0, u)
    formula, written with vectorised exp/log1p (np.logaddexp is a scalar loop, ~10× slower).
    """
    eps, g = shape.epsilon, shape.gamma
    u = m + eps
    u *= -g
    e = np.abs(u)
    np.negative(e, out=e)
    np.exp(e, out=e)
    softplus = np.log1p(e, out=e)
    softplus += np.maximum(u, 0.0)
    softplus /= g
    x_r = np.subtract(-eps, softplus, out=softplus)
    u *= 0.5
    s = np.tanh(u, out=u)
    s *= 0.5
    s += 0.5
    if not second:
        return x_r, s
    return x_r, s, -g * s * (1.0 - s)


@dataclass(frozen=True)
class RowValues:
    """Per distinct row (P, N): x = k q + t, ẋ = k v and the reference terms of (6), (7)."""

    x: np.ndarray
    x_dot: np.ndarray
    z: np.ndarray
    shifted_reference: np.ndarray   # x_r − t


@dataclass(frozen=True)
class AllGroups:
    """transform.all_groups for every robot."""

    rows: RowValues
    p: np.ndarray               # (G, n, N)
    value: np.ndarray           # (G, N) ½(|z|² + |p|²), +∞ where the group does not apply (x ≥ 0)

    def p_of(self, group: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(n, M): p of each robot of `cols` (M,) in its own `group` (M,)."""
        return self.p[group, :, cols].T


class GroupsOnDemand:
    """all_groups' rows for every robot, its per-group part (p, the selection values) for the robots
    that ask (shared_controller's _EveryGroupOnDemand for a batch): a sample in which the machine
    keeps its group, or the operator keeps authority, never needs them."""

    def __init__(self, table: GroupTable, q, v, ref: RowReference, lam: float):
        self.table, self.v = table, v
        self.rows, self.w = row_values(table, q, v, ref, lam)

    def values(self, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(p (G, n, M), value (G, M)) of the robots `cols` (M,)."""
        rows = self.rows
        return group_values(self.table, rows.x[:, cols], rows.z[:, cols], self.w[:, cols], self.v[:, cols])

    def p_of(self, group: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(n, M): p of each robot of `cols` (M,) in its own `group` (M,)."""
        p, _ = self.values(cols)
        return p[group, :, np.arange(cols.size)].T


@dataclass(frozen=True)
class RowReference:
    """The reference terms of (7) per distinct row (P, N) — functions of the wish alone."""

    x_r: np.ndarray
    x_r_dot: np.ndarray
    shifted: np.ndarray         # x_r − t


def row_reference(table: GroupTable, qd, qd_dot, shape: ReferenceShape) -> RowReference:
    """x_r = σ(k q_d + t), ẋ_r = σ'(k q_d + t) k q̇_d of (7) for every distinct row."""
    m = table.row_K @ qd
    m += table.row_T
    x_r, d1 = saturate(m, shape, second=False)
    x_r_dot = table.row_K @ qd_dot
    x_r_dot *= d1
    return RowReference(x_r, x_r_dot, x_r - table.row_T)


def all_groups(table: GroupTable, q, v, ref: RowReference, lam: float) -> AllGroups:
    """(6), (11) for every group and robot: the selection values ½(|z|² + |p|²)."""
    rows, w = row_values(table, q, v, ref, lam)
    p, value = group_values(table, rows.x, rows.z, w, v)
    return AllGroups(rows, p, value)


def row_values(table: GroupTable, q, v, ref: RowReference, lam: float) -> tuple[RowValues, np.ndarray]:
    """all_groups' part per distinct row: (x, ẋ, z; and w = (x/x_r)ẋ_r + (1 + λ)z, (P, N))."""
    x = table.row_K @ q
    x += table.row_T
    z = np.divide(x, ref.x_r)
    np.log(z, out=z)
    w = np.exp(z)
    w *= ref.x_r_dot
    w += (1.0 + lam) * z
    return RowValues(x, table.row_K @ v, z, ref.shifted), w


def group_values(table: GroupTable, x, z, w, v) -> tuple[np.ndarray, np.ndarray]:
    """all_groups' part per group, from the rows' x, z, w (P, M) and the velocities v (n, M):
    (p = v − K_g⁻¹ w_g (G, n, M), the selection values (G, M))."""
    v_ref = np.matmul(table.K_inv, w[table.group_rows])
    p = np.subtract(v[None], v_ref, out=v_ref)
    outside_rows = ~(x < 0.0)
    # z is NaN on rows with x ≥ 0; those rows make their groups inapplicable (+∞) and must not
    # reach the other groups' sums through the selection product (0 · NaN = NaN)
    value = table.group_sel @ np.where(outside_rows, 0.0, z * z)
    value += np.einsum("gim,gim->gm", p, p)     # |p|² per group, without a (G, n, N) temporary
    value *= 0.5
    value[((table.group_sel @ outside_rows) > 0.0) | np.isnan(value)] = np.inf
    return p, value


def reference_inside(table: GroupTable, shifted_reference: np.ndarray) -> np.ndarray:
    """(G, N): is group g's projected reference inside g's whole polytope (FeasibleSet.reference_inside)?

    `shifted_reference` (P, N) is x_r − t per distinct row; k_j q_r + t_j of every (group, row outside
    it) pair is one product with `reach`."""
    if table.reach_group.size == 0:
        return np.ones((table.groups, shifted_reference.shape[1]), dtype=bool)
    values = table.reach @ shifted_reference
    values += table.reach_T
    return (table.reach_sel @ ~(values <= 0.0)) == 0.0


def group_row_values(table: GroupTable, row_values: np.ndarray, group: np.ndarray) -> np.ndarray:
    """(n, N): the values (P, N) of each robot's `group` rows (`group` ≥ 0), one flat gather."""
    N = group.size
    index = table.group_rows_cols.take(group, axis=1)
    index *= N
    index += np.arange(N)
    return row_values.take(index)


def wish_admissible(table: GroupTable, qd: np.ndarray, epsilon: float) -> np.ndarray:
    """(N,): is each robot's wish q_d inside Q_a by at least ε (sharing.wish_admissible)?"""
    m = table.row_K @ qd
    m += table.row_T
    return np.any((table.region_sel @ (m > -epsilon)) == 0.0, axis=0)


def push_turned_away(table: GroupTable, row_x: np.ndarray, pushes: np.ndarray, wish_ok: np.ndarray,
                     containing: np.ndarray, bands: Bands) -> np.ndarray:
    """(N,): sharing.push_turned_away per robot — the wish admissible (`wish_ok`) and, in some region
    containing q (`containing`, (R, N)), k_j u_h ≤ 0 (`pushes`, (P, N): table.row_K @ u_h) on every row
    with −b_s < k_j q + t_j (`row_x`, (P, N))."""
    pushing = (row_x > -bands.standoff) & (pushes > 0.0)
    return wish_ok & np.any(containing & ((table.region_sel @ pushing) == 0.0), axis=0)


def projected_configuration(table: GroupTable, shifted_reference: np.ndarray, group: np.ndarray) -> np.ndarray:
    """q_r = K⁻¹(x_r − T) of each robot's `group` (n, N); NaN where the group is −1."""
    g = np.maximum(group, 0)
    offsets = group_row_values(table, shifted_reference, g)
    q_r = np.einsum("ijm,jm->im", table.K_inv_cols.take(g, axis=-1), offsets)
    none = group < 0
    if none.any():
        q_r[:, none] = np.nan
    return q_r


def allowance(x: np.ndarray, b: float) -> np.ndarray:
    """f_b(x) = 1/(x + b) − 1/b for x > −b, +∞ otherwise (sets.allowance)."""
    return np.where(x > -b, 1.0 / (x + b) - 1.0 / b, np.inf)


@dataclass(frozen=True)
class Situation:
    """sets.classify for every robot."""

    overall: np.ndarray         # (N,) SetClass values
    containing: np.ndarray      # (R, N) bool: region contains q
    hazard_rows: np.ndarray     # (P, N) bool: hazardous rows (meaningful in containing regions)
    margin: np.ndarray          # (N,) FeasibleSet.margin
    inside: np.ndarray          # (N,) FeasibleSet.contains

    def take(self, cols: np.ndarray) -> "Situation":
        return Situation(self.overall[cols], self.containing[:, cols], self.hazard_rows[:, cols], self.margin[cols],
                         self.inside[cols])


def classify(table: GroupTable, rows: RowValues, bands: Bands, seen: np.ndarray | None = None) -> Situation:
    """Definition 2 per polytope, then the union rule (sets.py).

    `seen` (P, N): the row values to classify by, if not rows.x — the rows seen through the
    fail-safe stop (backup.py's speed_aware_rows, which keeps every row's sign); containment and
    the margin are those of rows.x."""
    x, x_dot = rows.x, rows.x_dot
    s = x if seen is None else seen
    negative = x < 0.0
    near = (negative if seen is None else s < 0.0) & (s >= -bands.b1)
    hazard = near & ((x_dot >= allowance(s, bands.b1)) | ((s >= -bands.b0) & (x_dot > 0.0)))
    unsafe = ((s >= -bands.b2) & (x_dot > allowance(s, bands.b2))) | (s > -bands.standoff)
    containing = (table.region_sel @ ~negative) == 0.0
    any_hazard = (table.region_sel @ hazard) > 0.0
    any_unsafe = (table.region_sel @ unsafe) > 0.0
    region_class = np.where(any_hazard, HAZARD, np.where(any_unsafe, HYSTERESIS, SAFE))
    margin = -np.max(x[table.region_rows[0]], axis=0)
    for r in table.region_rows[1:]:
        np.maximum(margin, -np.max(x[r], axis=0), out=margin)
    any_safe = np.any(containing & (region_class == SAFE), axis=0)
    all_hazard = np.all(~containing | (region_class == HAZARD), axis=0)
    none = ~containing.any(axis=0)
    overall = np.where(none | (~any_safe & all_hazard), HAZARD, np.where(any_safe, SAFE, HYSTERESIS))
    return Situation(overall, containing, hazard, margin, ~none)


def missed_rows(table: GroupTable, situation: Situation) -> np.ndarray:
    """(G, N): hazardous rows of each group's polytope that the group does not contain."""
    return table.missed_sel @ situation.hazard_rows


def select_group(table: GroupTable, situation: Situation, value: np.ndarray, missed: np.ndarray,
                 ref_ok: np.ndarray) -> np.ndarray:
    """sharing.select_group for every robot: (N,) group index, −1 for none.

    Among the groups whose polytope contains q and whose value is finite, the least key
    (hazardous rows missed, reference outside its polytope, value), ties to the lowest index.
    """
    applicable = situation.containing[table.region_of] & np.isfinite(value)
    fewest = np.where(applicable, missed, np.inf).min(axis=0)
    best = applicable & (missed == fewest)
    least_outside = np.where(best, ~ref_ok, True).min(axis=0)
    best &= ~ref_ok == least_outside
    chosen = np.argmin(np.where(best, value, np.inf), axis=0)
    return np.where(best.any(axis=0), chosen, -1)
