"""The live view's 3D scene: the admissible set at the robot's heading, the robot, the projected
reference and the operator's wish, as one ``foxglove.SceneUpdate``. Pure: numbers in, a dict out.

The set is a union of polytopes {q : K q + T ≤ 0} in q = (x, y, ψ, …). Its slice through the
robot's current heading (every coordinate beyond the second held at the robot's) is, region by
region, a convex polygon in the (x, y) plane: the half-planes K[j, :2]·p ≤ −(T[j] + K[j, 2:]·q[2:]),
clipped to a square window of half-width ``half_width`` around the robot (a region may be
unbounded). Each region is drawn as a translucent fill (triangles) and its faces as lines; the
window's own edges are not faces and are not drawn. A row that does not involve x or y decides
the whole region at this heading (|ψ| < π/2, say): violated, the region is empty.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sharedctl.constraints import FeasibleSet, Polytope

from .foxglove_types import LINE_LIST, color, entity, point, pose

FRAME = "world"
WINDOW_EDGE = -1                # the label of a polygon edge that lies on the window, not on a face
DEFAULT_HALF_WIDTH = 4.0        # m
PLANE_NORMAL_MIN = 1e-9         # a row whose (x, y) part is shorter than this involves neither
MARKER_DIAMETER = 0.12          # m, the reference and the wish
SET_FILL = color(0.25, 0.75, 0.35, 0.22)
SET_FACE = color(0.10, 0.45, 0.20, 1.0)
REFERENCE_COLOR = color(0.10, 0.80, 0.20, 1.0)
WISH_COLOR = color(0.85, 0.20, 0.85, 1.0)
AUTHORITY_COLORS = {"human": color(0.20, 0.45, 0.95), "shared": color(0.95, 0.65, 0.10),
                    "machine": color(0.90, 0.20, 0.15)}


@dataclass(frozen=True)
class Slice:
    """One region's slice: polygon vertices (counter-clockwise) and, per vertex, the row its outgoing edge lies on."""

    vertices: tuple[tuple[float, float], ...]
    edge_rows: tuple[int, ...]           # row index of the region, or WINDOW_EDGE

    @property
    def empty(self) -> bool:
        return len(self.vertices) < 3

    def faces(self) -> list[tuple[tuple[float, float], tuple[float, float], int]]:
        """The edges that lie on a face of the region: (start, end, row)."""
        n = len(self.vertices)
        out = []
        for i in range(n if n >= 3 else 0):
            start, end = self.vertices[i], self.vertices[(i + 1) % n]
            if self.edge_rows[i] != WINDOW_EDGE and math.dist(start, end) > 1e-9:
                out.append((start, end, self.edge_rows[i]))
        return out

    def triangles(self) -> list[tuple[tuple[float, float], ...]]:
        """A fan over the convex polygon."""
        v = self.vertices
        return [(v[0], v[i], v[i + 1]) for i in range(1, len(v) - 1)] if len(v) >= 3 else []


def window(centre_x: float, centre_y: float, half_width: float) -> Slice:
    h = half_width
    corners = ((centre_x - h, centre_y - h), (centre_x + h, centre_y - h),
               (centre_x + h, centre_y + h), (centre_x - h, centre_y + h))
    return Slice(corners, (WINDOW_EDGE,) * 4)


def clip(polygon: Slice, a: np.ndarray, b: float, row: int) -> Slice:
    """The part of a convex polygon where a·p ≤ b (Sutherland–Hodgman), edges on the line labelled ``row``."""
    vertices, rows = polygon.vertices, polygon.edge_rows
    n = len(vertices)
    out: list[tuple[float, float]] = []
    out_rows: list[int] = []
    for i in range(n):
        p, q = vertices[i], vertices[(i + 1) % n]
        sp, sq = a[0] * p[0] + a[1] * p[1] - b, a[0] * q[0] + a[1] * q[1] - b
        if sp <= 0.0:
            out.append(p)
            out_rows.append(rows[i])
            if sq > 0.0:                      # leaving: the edge from the crossing runs along the line
                out.append(_crossing(p, q, sp, sq))
                out_rows.append(row)
        elif sq <= 0.0:                       # entering: the rest of this edge keeps its label
            out.append(_crossing(p, q, sp, sq))
            out_rows.append(rows[i])
    return Slice(tuple(out), tuple(out_rows))


def _crossing(p, q, sp: float, sq: float) -> tuple[float, float]:
    t = sp / (sp - sq)
    return (p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]))


def region_slice(region: Polytope, q, half_width: float) -> Slice:
    """The region's slice through q's coordinates beyond (x, y), inside the window around (q[0], q[1])."""
    q = np.asarray(q, dtype=float)
    polygon = window(q[0], q[1], half_width)
    rest = q[2:]
    for j in range(region.K.shape[0]):
        a = region.K[j, :2]
        b = -(region.T[j] + float(region.K[j, 2:] @ rest))
        if float(np.hypot(a[0], a[1])) < PLANE_NORMAL_MIN:
            if b < 0.0:
                return Slice((), ())
            continue
        polygon = clip(polygon, a, b, j)
        if polygon.empty:
            return Slice((), ())
    return polygon


def set_entity(feasible: FeasibleSet, q, stamp_ns: int, half_width: float = DEFAULT_HALF_WIDTH) -> dict:
    """The admissible set's slice at q as one entity: a fill and the faces of each region."""
    triangles, lines = [], []
    drawn = 0
    for region in feasible.regions:
        piece = region_slice(region, q, half_width)
        if piece.empty:
            continue
        drawn += 1
        triangles.append({"pose": pose(), "points": [point(x, y) for tri in piece.triangles() for x, y in tri],
                          "color": SET_FILL, "colors": [], "indices": []})
        segments = [point(x, y) for start, end, _ in piece.faces() for x, y in (start, end)]
        if segments:
            lines.append({"type": LINE_LIST, "pose": pose(z=0.002), "thickness": 0.03, "scale_invariant": False,
                          "points": segments, "color": SET_FACE, "colors": [], "indices": []})
    heading = ", ".join(f"{v:.3f}" for v in np.asarray(q, float)[2:])
    return entity("admissible_set", stamp_ns, FRAME,
                  {"regions": str(len(feasible.regions)), "drawn": str(drawn), "held": heading},
                  triangles=triangles, lines=lines)


def robot_entity(state, stamp_ns: int, radius: float) -> dict:
    """A disc at (x, y) in the authority's colour, an arrow along the heading (if q has one), a label."""
    q = state.q
    yaw = q[2] if len(q) > 2 else 0.0
    shade = AUTHORITY_COLORS.get(str(state.authority), color(0.6, 0.6, 0.6))
    arrows = [{"pose": pose(q[0], q[1], 0.06, yaw), "shaft_length": radius, "shaft_diameter": 0.03,
               "head_length": 0.4 * radius, "head_diameter": 0.08, "color": color(1.0, 1.0, 1.0)}] if len(q) > 2 else []
    label = f"{state.authority} k_s {state.k_s:.2f} margin {state.min_margin:.3f} m"
    return entity("robot", stamp_ns, FRAME, {"authority": str(state.authority)},
                  cylinders=[{"pose": pose(q[0], q[1], 0.025, yaw), "size": point(2 * radius, 2 * radius, 0.05),
                              "bottom_scale": 1.0, "top_scale": 1.0, "color": shade}],
                  arrows=arrows,
                  texts=[{"pose": pose(q[0], q[1], 0.3), "billboard": True, "font_size": 14.0,
                          "scale_invariant": True, "color": color(1.0, 1.0, 1.0), "text": label}])


def marker_entity(entity_id: str, where, stamp_ns: int, shade: dict) -> dict:
    d = MARKER_DIAMETER
    return entity(entity_id, stamp_ns, FRAME,
                  spheres=[{"pose": pose(where[0], where[1], d / 2), "size": point(d, d, d), "color": shade}])


def scene_update(state, stamp_ns: int, feasible: FeasibleSet | None = None, wish=None,
                 half_width: float = DEFAULT_HALF_WIDTH, robot_radius: float = 0.2) -> dict:
    """One ``foxglove.SceneUpdate`` of a RobotState: the set (if known), the robot, the projected
    reference q_ref and the operator's wish q_d (``wish``: the latest operator command's q_d, or None)."""
    entities = []
    if feasible is not None:
        entities.append(set_entity(feasible, state.q, stamp_ns, half_width))
    entities.append(robot_entity(state, stamp_ns, robot_radius))
    entities.append(marker_entity("reference", state.q_ref, stamp_ns, REFERENCE_COLOR))
    if wish is not None:
        entities.append(marker_entity("wish", wish, stamp_ns, WISH_COLOR))
    return {"deletions": [], "entities": entities}
