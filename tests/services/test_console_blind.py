"""The console goes hands-off when its operator cannot see (services/console/app.py): a frozen UI or old
telemetry. Threat: a frozen console kept sending its last deflection (docs/security.md)."""
import pytest

from sharedctl.protocol.messages import Authority, LinkHealth, RobotState, SetClass
from sharedctl.services.console.app import TELEMETRY_STALE, UI_STALE, ConsoleApp, ConsoleOptions, blind
from sharedctl.services.scenario_files import load


def state():
    return RobotState(seq=1, time=1.0, q=(-0.9, 3.0, 0.0), qd_hat=(0.0, 0.0, 0.0), q_ref=(-0.9, 3.0, 0.0),
                      group_classes=(SetClass.SAFE,), active_group=0, authority=Authority.HUMAN, k_s=0.0, k_h=1.0,
                      k_f=0.0, u_h=(0.0, 0.0, 0.0), u_f=(0.0, 0.0, 0.0), u_s=(0.0, 0.0, 0.0),
                      wheel_torques=(0.0, 0.0, 0.0), theta_hat=(0.0, 0.0, 0.0), min_margin=0.5, region_margins=(0.5,),
                      estop_active=False, lease_holder="op",
                      link=LinkHealth(operator_latency_ms=0.0, loss_fraction=0.0, staleness_ms=0.0,
                                      can_feedback_age_ms=0.0))


@pytest.fixture
def app():
    a = ConsoleApp(ConsoleOptions(scenario=load("paper_convex")))
    a.lease.holding = True
    return a


def drive(app, now, ui_at, state_at):
    """Space and an arrow pressed just before `now`; the UI loop last ran at `ui_at`, a RobotState came at
    `state_at`."""
    app.telemetry.state, app.telemetry.state_arrival = state(), state_at
    app.ui_alive_at = ui_at
    app.keyboard.joystick.press_all(["space", "up"], now - 0.01)
    return app.next_command(now)


def test_with_a_live_ui_and_fresh_telemetry_the_operators_deflection_goes_out(app):
    cmd = drive(app, 100.0, ui_at=99.98, state_at=99.98)
    assert cmd.deadman and any(cmd.joystick) and app.blind is None


@pytest.mark.parametrize("ui_at, state_at, why", [
    (100.0 - UI_STALE - 0.1, 99.98, "UI frozen"),
    (99.98, 100.0 - TELEMETRY_STALE - 0.1, "telemetry"),
])
def test_a_frozen_ui_or_old_telemetry_sends_hands_off_and_still_an_estop(app, ui_at, state_at, why):
    cmd = drive(app, 100.0, ui_at, state_at)
    assert not cmd.deadman and not any(cmd.joystick) and cmd.q_d == (-0.9, 3.0, 0.0)
    assert why in app.blind and app.blind_commands == 1
    app.keyboard.joystick.press("x", 100.01)
    assert app.next_command(100.02).estop                     # an estop request always goes out


def test_blind_names_the_reason():
    assert blind(10.0, 9.9, 9.9) is None
    assert blind(10.0, 9.0, 9.9).startswith("console UI frozen for 1.0 s")
    assert blind(10.0, 9.9, None) == "no telemetry yet"
    assert blind(10.0, 9.9, 8.0) == "telemetry 2.0 s old"
