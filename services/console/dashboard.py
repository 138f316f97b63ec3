"""The console's dashboard: a `DashboardView` (plain data) in, rich renderables out. Pure.

Panels: the map (feasible set, robot, trail, projected reference, the operator's wish); the
authority (set class per constraint group, who drives, k_s and k_h/k_f as bars); the link
(operator latency, loss, staleness, CAN feedback age, age of the telemetry); estimates and
margins (θ̂, q, q̇̂, min and per-region margins); the operator (what this console sends); the
tail of the event log. Everything renders before the first RobotState too ("waiting").
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from rich.console import Group
from rich.layout import Layout
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from sharedctl.protocol.messages import Authority, OperatorCommand, RobotState, SetClass

from .map_view import MapFrame, axis_caption, render_map

CLASS_STYLE = {SetClass.SAFE: "green", SetClass.HYSTERESIS: "yellow", SetClass.HAZARD: "bold red"}
AUTHORITY_STYLE = {Authority.HUMAN: "bold green", Authority.SHARED: "bold yellow", Authority.MACHINE: "bold red"}
SEVERITY_STYLE = {"debug": "grey50", "info": "", "warning": "yellow", "error": "red", "critical": "bold red"}
STALE_S = 0.5   # telemetry older than this is shown as stale


@dataclass
class DashboardView:
    """Everything the dashboard shows; the app fills it, the renderer only reads it."""

    title: str = "sharedctl console"
    mode: str = "keyboard"                   # "keyboard" | "script"
    state: RobotState | None = None
    state_age: float | None = None           # s since the last RobotState arrived
    states_received: int = 0
    command: OperatorCommand | None = None   # the last command sent
    script_time: float | None = None         # s into the script (script mode)
    events: deque = field(default_factory=lambda: deque(maxlen=6))
    trail: deque = field(default_factory=lambda: deque(maxlen=400))
    frame: MapFrame | None = None
    grid: list | None = None                 # map background (map_view.background)
    keys_help: str = ""
    time_origin: float = 0.0                 # s on the controller's clock shown as t = 0 (its first RobotState)
    control: str = ""                        # this console's lease status (lease_client.py)


def bar(value: float, width: int = 20, style: str = "cyan") -> Text:
    """A horizontal bar for a value in [0, 1], with the number."""
    value = min(1.0, max(0.0, float(value)))
    filled = int(round(value * width))
    text = Text("█" * filled, style=style)
    text.append("░" * (width - filled), style="grey30")
    text.append(f" {value:.2f}")
    return text


def signed_bar(value: float, width: int = 9) -> Text:
    """A centred bar for a value in [−1, 1] (a joystick axis)."""
    value = min(1.0, max(-1.0, float(value)))
    cells = [" "] * (2 * width + 1)
    cells[width] = "│"
    n = int(round(abs(value) * width))
    for i in range(1, n + 1):
        cells[width + (i if value > 0 else -i)] = "█"
    text = Text("[" + "".join(cells) + "]", style="magenta")
    text.append(f" {value:+.2f}")
    return text


def _vec(values, fmt: str = "{:+.3f}") -> str:
    return "(" + ", ".join(fmt.format(v) for v in values) + ")"


def authority_panel(state: RobotState | None) -> Panel:
    if state is None:
        return Panel(Text("waiting for telemetry …", style="grey50"), title="authority")
    table = Table.grid(padding=(0, 1))
    table.add_column(style="bold")
    table.add_column()
    table.add_row("authority", Text(state.authority.value.upper(), style=AUTHORITY_STYLE[state.authority]))
    classes = Text()
    for i, cls in enumerate(state.group_classes):
        mark = "▶" if i == state.active_group else " "
        classes.append(f"{mark}{i}:{cls.value} ", style=CLASS_STYLE[cls])
    table.add_row("set", classes if state.group_classes else Text("–"))
    active = "–" if state.active_group is None else str(state.active_group)
    table.add_row("group", active)
    table.add_row("k_s", bar(state.k_s, style="green"))
    table.add_row("k_h", bar(state.k_h, style="magenta"))
    table.add_row("k_f", bar(state.k_f, style="red"))
    lease = state.lease_holder or "–"
    table.add_row("lease", lease)
    if state.estop_active:
        table.add_row("ESTOP", Text("ACTIVE", style="bold white on red"))
    return Panel(table, title="authority")


def link_panel(view: DashboardView) -> Panel:
    state = view.state
    table = Table.grid(padding=(0, 1))
    table.add_column(style="bold")
    table.add_column(justify="right")
    if view.state_age is None:
        table.add_row("telemetry", Text("none yet", style="grey50"))
    else:
        stale = view.state_age > STALE_S
        table.add_row("telemetry age", Text(f"{1e3 * view.state_age:.0f} ms", style="bold red" if stale else "green"))
    table.add_row("states received", str(view.states_received))
    if state is not None:
        link = state.link
        table.add_row("operator latency", f"{link.operator_latency_ms:.1f} ms")
        table.add_row("loss", f"{100 * link.loss_fraction:.1f} %")
        table.add_row("staleness", Text(f"{link.staleness_ms:.0f} ms", style="red" if link.staleness_ms > 300 else ""))
        table.add_row("CAN feedback age", Text(f"{link.can_feedback_age_ms:.1f} ms",
                                               style="red" if link.can_feedback_age_ms > 50 else ""))
        table.add_row("rejected msgs",
                      Text(str(link.rejected_messages), style="yellow" if link.rejected_messages else ""))
    return Panel(table, title="link")


def estimates_panel(state: RobotState | None, origin: float = 0.0) -> Panel:
    if state is None:
        return Panel(Text("–", style="grey50"), title="estimates and margins")
    table = Table.grid(padding=(0, 1))
    table.add_column(style="bold")
    table.add_column()
    table.add_row("t", f"{state.time - origin:.2f} s  (seq {state.seq})")
    table.add_row("q", _vec(state.q))
    table.add_row("q̇̂", _vec(state.qd_hat))
    table.add_row("q_ref", _vec(state.q_ref))
    table.add_row("θ̂", _vec(state.theta_hat, "{:.3f}"))
    table.add_row("u_h / u_f", _vec(state.u_h, "{:+.1f}") + " / " + _vec(state.u_f, "{:+.1f}"))
    table.add_row("u_s", _vec(state.u_s, "{:+.1f}"))
    table.add_row("τ wheels", _vec(state.wheel_torques, "{:+.2f}") + " N·m")
    style = "bold red" if state.min_margin <= 0 else ("yellow" if state.min_margin < 0.05 else "green")
    table.add_row("min margin", Text(f"{state.min_margin:.3f} m", style=style))
    if state.region_margins:
        table.add_row("region margins", _vec(state.region_margins, "{:.3f}"))
    return Panel(table, title="estimates and margins")


def operator_panel(view: DashboardView) -> Panel:
    cmd = view.command
    table = Table.grid(padding=(0, 1))
    table.add_column(style="bold")
    table.add_column()
    table.add_row("mode", view.mode + (f"  t = {view.script_time:.1f} s" if view.script_time is not None else ""))
    if view.control:
        table.add_row("control",
                      Text(view.control, style="green" if view.control.startswith("held by this") else "yellow"))
    if cmd is None:
        table.add_row("sent", Text("nothing yet", style="grey50"))
    else:
        for axis, value in zip(("x", "y", "ψ"), cmd.joystick):
            table.add_row(f"stick {axis}", signed_bar(value))
        table.add_row("deadman", Text("HELD", style="green") if cmd.deadman else Text("released", style="yellow"))
        table.add_row("estop", Text("REQUESTED", style="bold white on red") if cmd.estop else "–")
        table.add_row("request", cmd.control_request.value)
        table.add_row("wish q_d", _vec(cmd.q_d))
        table.add_row("seq", str(cmd.seq))
    return Panel(table, title="operator")


def events_panel(events, origin: float = 0.0) -> Panel:
    text = Text()
    for i, ev in enumerate(events):
        if i:
            text.append("\n")
        text.append(f"{ev.time - origin:7.2f} ", style="grey50")
        text.append(f"{ev.kind.value:<15}", style=SEVERITY_STYLE.get(ev.severity.value, ""))
        text.append(f" {ev.source}: {ev.text}")
    if not events:
        text.append("no events", style="grey50")
    return Panel(text, title="events")


def map_panel(view: DashboardView) -> Panel:
    if view.frame is None or view.grid is None:
        return Panel(Text("no map (no scenario)", style="grey50"), title="map")
    state, cmd = view.state, view.command
    body = render_map(
        view.grid, view.frame,
        robot=None if state is None else state.q[:2],
        trail=list(view.trail),
        reference=None if state is None else state.q_ref[:2],
        wish=None if cmd is None else cmd.q_d[:2],
    )
    return Panel(Group(body, Text(axis_caption(view.frame), style="grey62", overflow="ellipsis", no_wrap=True)),
                 title="map (x → , y ↑)")


def render(view: DashboardView) -> Layout:
    """The whole screen; the map column is as wide as the map (`map_size` gives the map for a screen)."""
    layout = Layout(name="root")
    header = Text(f" {view.title} ", style="bold white on dark_blue")
    if view.keys_help:
        header.append("  " + view.keys_help, style="grey70")
    layout.split_column(Layout(header, name="header", size=1), Layout(name="body"), Layout(name="events", size=8))
    map_width = None if view.frame is None else view.frame.cols + 4
    map_height = 12 if view.frame is None else view.frame.rows + 3
    layout["body"].split_row(Layout(name="left", size=map_width, ratio=3), Layout(name="right", ratio=2))
    layout["left"].split_column(Layout(map_panel(view), name="map", size=map_height), Layout(name="lower"))
    layout["lower"].split_row(Layout(authority_panel(view.state)), Layout(link_panel(view)))
    layout["right"].split_column(Layout(estimates_panel(view.state, view.time_origin), size=13),
                                 Layout(operator_panel(view)))
    layout["events"].update(events_panel(view.events, view.time_origin))
    return layout


def map_size(width: int, height: int) -> tuple[int, int]:
    """Map cells (cols, rows) that fit a screen of width × height characters next to the other panels."""
    return max(30, width - 68), max(8, height - 24)


def render_text(view: DashboardView, width: int = 160, height: int = 48) -> str:
    """The dashboard as plain text (tests, captures)."""
    from io import StringIO

    from rich.console import Console

    console = Console(file=StringIO(), width=width, height=height, record=True, color_system=None, legacy_windows=False)
    console.print(render(view), height=height)
    return console.export_text()
