"""A text map of the feasible set in the (x, y) plane, with the robot, its trail, the projected
reference and the operator's wish. Pure: numbers in, a rich `Text` out.

Each character cell is one point of the plane (a cell is twice as tall as it is wide, as
terminal characters are); the background marks where the feasible set is (at the robot's
current yaw): `·` inside a region (the region's digit on the cells along its faces), `░`
outside every region (an obstacle or out of bounds).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rich.text import Text

from sharedctl.constraints import FeasibleSet

ROBOT, TRAIL, REFERENCE, WISH = "●", "•", "◎", "✕"
OUTSIDE, INSIDE = "░", "·"
STYLES = {ROBOT: "bold bright_white on blue", TRAIL: "cyan", REFERENCE: "bold green", WISH: "bold magenta",
          OUTSIDE: "grey35", INSIDE: "grey23"}


@dataclass(frozen=True)
class MapFrame:
    """The plotted window: x in [x_min, x_max], y in [y_min, y_max], cols × rows cells."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float
    cols: int
    rows: int

    @staticmethod
    def around(points, cols: int = 56, rows: int = 18, pad: float = 0.5, min_span: float = 2.0) -> "MapFrame":
        """The smallest window with square metres (a row is 2 columns' width) holding the points, padded."""
        pts = np.asarray(points, float).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        lo = pts.min(axis=0) - pad if pts.size else np.array([-1.0, -1.0])
        hi = pts.max(axis=0) + pad if pts.size else np.array([1.0, 1.0])
        span = np.maximum(hi - lo, min_span)
        centre = (lo + hi) / 2
        cell = max(span[0] / cols, span[1] / (2 * rows))   # metres per column; a row is 2 cells high
        half = np.array([cell * cols, 2 * cell * rows]) / 2
        return MapFrame(centre[0] - half[0], centre[0] + half[0], centre[1] - half[1], centre[1] + half[1], cols, rows)

    def cell(self, x: float, y: float) -> tuple[int, int] | None:
        """(row, col) of a point, or None outside the window."""
        if not (np.isfinite(x) and np.isfinite(y)):
            return None
        col = int((x - self.x_min) / (self.x_max - self.x_min) * self.cols)
        row = int((self.y_max - y) / (self.y_max - self.y_min) * self.rows)
        if 0 <= col < self.cols and 0 <= row < self.rows:
            return row, col
        return None

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        xs = self.x_min + (np.arange(self.cols) + 0.5) * (self.x_max - self.x_min) / self.cols
        ys = self.y_max - (np.arange(self.rows) + 0.5) * (self.y_max - self.y_min) / self.rows
        return xs, ys


def background(feasible: FeasibleSet, frame: MapFrame, yaw: float = 0.0, rest=None) -> list[list[str]]:
    """The set at yaw `yaw` (other coordinates beyond the third from `rest`): a grid of characters."""
    xs, ys = frame.centres()
    n = feasible.n
    grid = [[OUTSIDE] * frame.cols for _ in range(frame.rows)]
    q = np.zeros(n) if rest is None else np.asarray(rest, float).copy()
    if n > 2:
        q[2] = yaw
    face = (frame.x_max - frame.x_min) / frame.cols    # within one cell width of a face
    for r, y in enumerate(ys):
        for c, x in enumerate(xs):
            q[0], q[1] = x, y
            margins = feasible.region_margins(q)
            best = int(np.argmax(margins))
            if margins[best] > 0:
                grid[r][c] = str(best + 1) if len(margins) > 1 and margins[best] < face else INSIDE
    return grid


def render_map(grid: list[list[str]], frame: MapFrame, *, robot=None, trail=(), reference=None, wish=None) -> Text:
    """The background with the marks drawn on top (robot over reference over wish over trail)."""
    cells = [row[:] for row in grid]
    for point in trail:
        _put(cells, frame, point, TRAIL)
    for point, mark in ((wish, WISH), (reference, REFERENCE), (robot, ROBOT)):
        if point is not None:
            _put(cells, frame, point, mark)
    text = Text(no_wrap=True, overflow="crop")
    for r, row in enumerate(cells):
        start = 0
        for c in range(1, len(row) + 1):       # one append per run of equally styled cells
            if c == len(row) or _style(row[c]) != _style(row[start]):
                text.append("".join(row[start:c]), _style(row[start]))
                start = c
        if r < len(cells) - 1:
            text.append("\n")
    return text


def _style(ch: str) -> str:
    return STYLES.get(ch, "yellow" if ch.isdigit() else "")


def axis_caption(frame: MapFrame) -> str:
    return (f"x {frame.x_min:+.1f}…{frame.x_max:+.1f} m, y {frame.y_min:+.1f}…{frame.y_max:+.1f} m  "
            f"{ROBOT} robot {TRAIL} trail {REFERENCE} reference {WISH} wish {OUTSIDE} outside")


def _put(cells, frame: MapFrame, point, mark: str) -> None:
    where = frame.cell(float(point[0]), float(point[1]))
    if where is not None:
        cells[where[0]][where[1]] = mark
