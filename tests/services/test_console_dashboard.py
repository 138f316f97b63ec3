"""The dashboard renders telemetry to text without a terminal."""
from collections import deque

import pytest

from sharedctl.protocol.messages import (
    Authority, Event, EventKind, LinkHealth, RobotState, SetClass, Severity,
)
from sharedctl.services.console.dashboard import DashboardView, bar, render_text, signed_bar
from sharedctl.services.console.map_view import INSIDE, OUTSIDE, ROBOT, MapFrame, background, render_map
from sharedctl.services.console.operator import ScriptedCommandSource
from sharedctl.services.scenario_files import load


@pytest.fixture(scope="module")
def nonconvex():
    loop, q0, _ = load("paper_nonconvex").closed_loop()
    return loop, q0


def robot_state(**over) -> RobotState:
    fields = dict(
        seq=4711, time=12.34, q=(-0.05, 1.2, 0.01), qd_hat=(0.0, -0.15, 0.0), q_ref=(-0.04, 1.1, 0.0),
        group_classes=(SetClass.HAZARD, SetClass.SAFE), active_group=0, authority=Authority.MACHINE,
        k_s=0.0, k_h=0.25, k_f=0.75, u_h=(20.0, -1.0, 0.0), u_f=(-3.5, 0.0, 0.0), u_s=(-3.5, 0.0, 0.0),
        wheel_torques=(0.11, -0.22, 0.33), theta_hat=(4.7765, 0.0, 0.0), min_margin=0.0421,
        region_margins=(0.0421, -1.2), estop_active=False, lease_holder="operator",
        link=LinkHealth(operator_latency_ms=1.7, loss_fraction=0.02, staleness_ms=13.0, can_feedback_age_ms=2.5),
    )
    fields.update(over)
    return RobotState(**fields)


def view_with(nonconvex, **over) -> DashboardView:
    loop, q0 = nonconvex
    frame = MapFrame.around([q0[:2], (2.1, -1.5)], cols=60, rows=16)
    view = DashboardView(frame=frame, grid=background(loop.feasible, frame), mode="script", script_time=12.3,
                         state_age=0.018, states_received=600)
    view.state = robot_state()
    view.command = ScriptedCommandSource(loop.human).command(12.3, view.state, send_time=1.0)
    view.events = deque([Event(seq=1, time=9.87, kind=EventKind.AUTHORITY_CHANGE, severity=Severity.INFO,
                               source="controller", text="human -> machine")])
    for key, value in over.items():
        setattr(view, key, value)
    return view


def test_the_authority_panel_shows_who_drives_and_the_weights(nonconvex):
    text = render_text(view_with(nonconvex))
    assert "MACHINE" in text
    assert "▶0:hazard" in text and "1:safe" in text
    assert "0.25" in text and "0.75" in text


def test_the_link_panel_shows_latency_loss_staleness_and_can_age(nonconvex):
    text = render_text(view_with(nonconvex))
    assert "1.7 ms" in text and "2.0 %" in text and "13 ms" in text and "2.5 ms" in text
    assert "18 ms" in text   # telemetry age


def test_the_estimates_panel_shows_theta_hat_and_margins(nonconvex):
    text = render_text(view_with(nonconvex))
    assert "4.777" in text and "0.042 m" in text and "-1.200" in text
    assert "seq 4711" in text


def test_the_event_log_tail_is_shown(nonconvex):
    assert "authority_change controller: human -> machine" in render_text(view_with(nonconvex))


def test_an_estop_is_shown_prominently(nonconvex):
    assert "ACTIVE" in render_text(view_with(nonconvex, state=robot_state(estop_active=True)))


def test_before_the_first_state_the_dashboard_says_it_is_waiting():
    text = render_text(DashboardView())
    assert "waiting for telemetry" in text and "none yet" in text and "nothing yet" in text


def test_the_map_marks_the_robot_inside_and_the_obstacle_outside(nonconvex):
    loop, _ = nonconvex
    frame = MapFrame(-2.0, 2.0, -2.0, 2.0, cols=40, rows=10)
    grid = background(loop.feasible, frame)
    assert grid[frame.cell(-1.0, 1.0)[0]][frame.cell(-1.0, 1.0)[1]] == INSIDE
    assert grid[frame.cell(1.0, 1.0)[0]][frame.cell(1.0, 1.0)[1]] == OUTSIDE
    lines = render_map(grid, frame, robot=(-1.0, 1.0)).plain.splitlines()
    row, col = frame.cell(-1.0, 1.0)
    assert lines[row][col] == ROBOT


def test_the_map_window_keeps_square_metres():
    frame = MapFrame.around([(0.0, 0.0), (4.0, 1.0)], cols=40, rows=10)
    metres_per_col = (frame.x_max - frame.x_min) / frame.cols
    metres_per_row = (frame.y_max - frame.y_min) / frame.rows
    assert metres_per_row == pytest.approx(2 * metres_per_col)


def test_bars_show_their_value():
    assert bar(0.5, width=10).plain == "█████░░░░░ 0.50"
    assert signed_bar(-1.0, width=3).plain == "[███│   ] -1.00"
