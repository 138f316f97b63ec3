"""Admissible sets: polytopes {q : K q + T ≤ 0} (paper (2)) and unions of them.

A *group* (paper (3)) is n rows of one polytope with an invertible n×n matrix K_i;
its coordinates are x^i = K_i q + T_i and feasibility means every x^i_j < 0.

* m < n (or rank K < n): the polytope is completed with far rows e_jᵀ q − α ≤ 0
  along coordinate directions missing from the row space (Section 3.1: "augment
  constraints … with a sufficiently large constant α").
* m > n: every choice of n rows with a well-conditioned K_i is a group.
* A non-convex feasible set is a union of polytopes; each polytope brings its own
  groups, and a group applies only where its polytope contains q.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple

import numpy as np

from .short_vectors import matvec, rows_of


class ConstraintError(ValueError):
    """A constraint set that cannot be used (bad shapes, empty, no invertible group)."""


@dataclass(frozen=True)
class Polytope:
    """{q : K q + T ≤ 0}, rows normalised to unit length so slack is a distance."""

    K: np.ndarray
    T: np.ndarray

    @staticmethod
    def from_rows(K, T) -> "Polytope":
        K = np.atleast_2d(np.asarray(K, dtype=float))
        T = np.asarray(T, dtype=float).reshape(-1)
        if K.shape[0] != T.shape[0] or K.shape[0] == 0:
            raise ConstraintError(f"K has {K.shape[0]} rows but T has {T.shape[0]} entries")
        if not (np.all(np.isfinite(K)) and np.all(np.isfinite(T))):
            raise ConstraintError("K and T must be finite")
        norms = np.linalg.norm(K, axis=1)
        if np.any(norms < 1e-12):
            raise ConstraintError("a row of K is zero")
        return Polytope(K / norms[:, None], T / norms)

    @property
    def n(self) -> int:
        return self.K.shape[1]

    def values(self, q: np.ndarray) -> np.ndarray:
        """K q + T: negative inside, zero on a face."""
        return self.K @ q + self.T

    def margin(self, q: np.ndarray) -> float:
        """Smallest slack −max_j (K q + T)_j: positive inside, negative outside."""
        return float(-np.max(self.values(q)))

    def contains(self, q: np.ndarray) -> bool:
        return bool(np.all(self.values(q) < 0.0))


@dataclass(frozen=True)
class ConstraintGroup:
    """n rows of one polytope with invertible K_i (paper (3))."""

    region: int                 # index of the polytope in the feasible set
    rows: tuple[int, ...]       # row indices into the (completed) polytope
    K: np.ndarray               # n×n
    T: np.ndarray               # n
    K_inv: np.ndarray

    def values(self, q: np.ndarray) -> np.ndarray:
        """x^i = K_i q + T_i."""
        return self.K @ q + self.T

    @cached_property
    def floats(self) -> "GroupFloats":
        """K_i, T_i, K_i⁻¹ and K_iᵀ as tuples of Python floats (for the per-sample arithmetic)."""
        return GroupFloats(rows_of(self.K), tuple(self.T.tolist()), rows_of(self.K_inv), rows_of(self.K.T))


class GroupFloats(NamedTuple):
    """One group's matrices as row tuples of Python floats (short_vectors)."""

    K: tuple
    T: tuple
    K_inv: tuple
    K_transposed: tuple


@dataclass(frozen=True)
class GroupStack:
    """All groups' matrices stacked, for evaluating every group at once.

    `K_rows` (G·n × n) and `T_rows` (G·n) are the same rows flattened: one matrix product gives
    every group's x = K q + T (transform.all_groups). `K_inv_blocks` (G·n × G·n) holds every K⁻¹
    on its diagonal: one product maps every group's vector back at once.
    """

    K: np.ndarray       # G×n×n
    T: np.ndarray       # G×n
    K_inv: np.ndarray   # G×n×n
    K_rows: np.ndarray = field(init=False, repr=False, compare=False)
    T_rows: np.ndarray = field(init=False, repr=False, compare=False)
    K_inv_blocks: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        G, n = self.T.shape
        blocks = np.zeros((G * n, G * n))
        for g in range(G):
            blocks[g * n:(g + 1) * n, g * n:(g + 1) * n] = self.K_inv[g]
        object.__setattr__(self, "K_rows", np.ascontiguousarray(self.K.reshape(-1, self.K.shape[-1])))
        object.__setattr__(self, "T_rows", np.ascontiguousarray(self.T.reshape(-1)))
        object.__setattr__(self, "K_inv_blocks", blocks)

    @staticmethod
    def of(groups) -> "GroupStack":
        return GroupStack(np.stack([g.K for g in groups]), np.stack([g.T for g in groups]),
                          np.stack([g.K_inv for g in groups]))


@dataclass(frozen=True)
class FeasibleSet:
    """A union of polytopes Q_a = ∪_r {K_r q + T_r ≤ 0}, with its constraint groups."""

    regions: tuple[Polytope, ...]
    groups: tuple[ConstraintGroup, ...]
    completion_distance: float
    stack: GroupStack

    @staticmethod
    def from_regions(regions, completion_distance: float = 1.0e3, max_condition: float = 1.0e6) -> "FeasibleSet":
        """Complete every polytope to full rank and enumerate its groups."""
        polys = tuple(complete(r, completion_distance) for r in regions)
        if not polys:
            raise ConstraintError("a feasible set needs at least one region")
        n = polys[0].n
        if any(p.n != n for p in polys):
            raise ConstraintError("all regions must have the same dimension")
        groups: list[ConstraintGroup] = []
        for index, poly in enumerate(polys):
            found = enumerate_groups(poly, index, max_condition)
            if not found:
                raise ConstraintError(f"region {index} has no invertible group of {n} rows")
            groups.extend(found)
        return FeasibleSet(polys, tuple(groups), completion_distance, GroupStack.of(groups))

    @property
    def n(self) -> int:
        return self.regions[0].n

    def containing_regions(self, q: np.ndarray) -> list[int]:
        """Indices of the polytopes that contain q (strictly)."""
        return [i for i, r in enumerate(self.regions) if r.contains(q)]

    def contains(self, q: np.ndarray) -> bool:
        return any(r.contains(q) for r in self.regions)

    def margin(self, q: np.ndarray) -> float:
        """The best region's smallest slack: > 0 inside the union, ≤ 0 outside."""
        return max(r.margin(q) for r in self.regions)

    def region_margins(self, q: np.ndarray, values: list | None = None) -> np.ndarray:
        """Each region's smallest slack (Polytope.margin), from one product with the stacked rows
        (or from `values`, the first list of `row_values(q, ·)`)."""
        rows = self._rows
        if values is None:
            values = (rows.K @ q + rows.T).tolist()
        return np.array([-_max_or_nan(values[a:b]) for a, b in rows.spans])

    @property
    def group_row_sets(self) -> tuple[frozenset, ...]:
        """Each group's row indices as a set (select_group's covering test)."""
        cached = self.__dict__.get("_row_sets_cache")
        if cached is None:
            cached = tuple(frozenset(g.rows) for g in self.groups)
            object.__setattr__(self, "_row_sets_cache", cached)
        return cached

    def row_values(self, q, v) -> tuple[list, list]:
        """K q + T and K v for the rows of every region, stacked (spans in `row_spans`), as floats.
        `q`, `v`: arrays or lists of floats."""
        rows = self._rows
        K = rows.K_floats
        return [kq + t for kq, t in zip(matvec(K, _as_list(q)), rows.T_floats)], matvec(K, _as_list(v))

    @property
    def row_ids(self) -> tuple[int, ...]:
        """Each stacked row's distinct id: rows equal in k and t (a face two polytopes share) have one id,
        numbered in the order of first appearance."""
        cached = self.__dict__.get("_row_ids_cache")
        if cached is None:
            keys: dict = {}
            cached = tuple(keys.setdefault((tuple(r.K[j]), float(r.T[j])), len(keys))
                           for r in self.regions for j in range(r.K.shape[0]))
            object.__setattr__(self, "_row_ids_cache", cached)
        return cached

    def row_rates(self, v) -> list:
        """K v for the rows of every region, stacked as in `row_values`."""
        return matvec(self._rows.K_floats, _as_list(v))

    def group_rows(self, g: int, rows: tuple[list, list]) -> tuple[list, list]:
        """Group g's x = K_g q + T_g and ẋ = K_g v, picked from `rows` = row_values(q, v)."""
        values, rates = rows
        picks = self._rows.group_rows[g]
        return [values[i] for i in picks], [rates[i] for i in picks]

    @property
    def row_matrix(self) -> np.ndarray:
        """Every region's rows K stacked, in the order of `row_values`."""
        return self._rows.K

    @property
    def row_spans(self) -> tuple[tuple[int, int], ...]:
        """(first, end) row of each region in the stacked rows of `row_values`."""
        return self._rows.spans

    def reference_inside(self, points: np.ndarray) -> np.ndarray:
        """For G points (one per group), is point g inside group g's own polytope?"""
        rows = self._rows
        outside = ~(points @ rows.K.T + rows.T <= 0.0) & rows.own     # NaN counts as outside
        return ~outside.any(axis=1)

    def point_inside_group_region(self, g: int, point) -> bool:
        """reference_inside for one group: is `point` (floats) inside group g's polytope (NaN: outside)?"""
        K, T = self._rows.by_region[self.groups[g].region]
        return all(kp + t <= 0.0 for kp, t in zip(matvec(K, point), T))

    @property
    def _rows(self) -> "_StackedRows":
        cached = self.__dict__.get("_rows_cache")
        if cached is None:
            cached = _StackedRows.of(self)
            object.__setattr__(self, "_rows_cache", cached)
        return cached

    @property
    def _members(self) -> list[np.ndarray]:
        cached = self.__dict__.get("_members_cache")
        if cached is None:
            cached = [np.array([g for g, grp in enumerate(self.groups) if grp.region == r], dtype=int)
                      for r in range(len(self.regions))]
            object.__setattr__(self, "_members_cache", cached)
        return cached

    def applicable_groups(self, q: np.ndarray) -> list[int]:
        """Groups whose polytope contains q ("which groups apply here")."""
        inside = set(self.containing_regions(q))
        return [g for g, grp in enumerate(self.groups) if grp.region in inside]


@dataclass(frozen=True)
class _StackedRows:
    """Every region's rows in one matrix: `spans[r]` are region r's rows; `own[g, j]` says row j
    belongs to group g's polytope."""

    K: np.ndarray
    T: np.ndarray
    spans: tuple[tuple[int, int], ...]
    own: np.ndarray
    group_rows: tuple[tuple[int, ...], ...]     # group g's rows, as indices into the stacked rows
    K_floats: tuple = field(init=False, repr=False, compare=False)
    T_floats: tuple = field(init=False, repr=False, compare=False)
    by_region: tuple = field(init=False, repr=False, compare=False)    # (K rows, T) of each region, as floats

    def __post_init__(self):
        object.__setattr__(self, "K_floats", rows_of(self.K))
        object.__setattr__(self, "T_floats", tuple(self.T.tolist()))
        object.__setattr__(self, "by_region", tuple((self.K_floats[a:b], self.T_floats[a:b]) for a, b in self.spans))

    @staticmethod
    def of(feasible: FeasibleSet) -> "_StackedRows":
        sizes = [r.K.shape[0] for r in feasible.regions]
        ends = np.cumsum(sizes).tolist()
        spans = tuple((end - size, end) for size, end in zip(sizes, ends))
        own = np.zeros((len(feasible.groups), ends[-1]), dtype=bool)
        for g, grp in enumerate(feasible.groups):
            a, b = spans[grp.region]
            own[g, a:b] = True
        group_rows = tuple(tuple(spans[grp.region][0] + j for j in grp.rows) for grp in feasible.groups)
        return _StackedRows(np.vstack([r.K for r in feasible.regions]), np.concatenate([r.T for r in feasible.regions]),
                            spans, own, group_rows)


def _as_list(vector) -> list:
    return vector.tolist() if isinstance(vector, np.ndarray) else vector


def _max_or_nan(values: list) -> float:
    """max() that, like np.max, returns NaN when any value is NaN."""
    top = max(values)
    return top if all(v == v for v in values) else float("nan")


def complete(poly: Polytope, distance: float) -> Polytope:
    """Add far rows e_jᵀ q − distance ≤ 0 until the rows span R^n."""
    K, T = poly.K, poly.T
    n = poly.n
    rank = np.linalg.matrix_rank(K, tol=1e-9)
    for j in range(n):
        if rank == n:
            break
        e = np.zeros(n)
        e[j] = 1.0
        candidate = np.vstack([K, e])
        if np.linalg.matrix_rank(candidate, tol=1e-9) > rank:
            K, T = candidate, np.append(T, -distance)
            rank += 1
    return Polytope(K, T)


def enumerate_groups(poly: Polytope, region: int, max_condition: float) -> list[ConstraintGroup]:
    """Every choice of n rows whose K_i is invertible (condition number below max_condition)."""
    n = poly.n
    groups = []
    for rows in itertools.combinations(range(poly.K.shape[0]), n):
        K = poly.K[list(rows)]
        if np.linalg.cond(K) > max_condition:
            continue
        groups.append(ConstraintGroup(region, rows, K, poly.T[list(rows)], np.linalg.inv(K)))
    return groups
