"""Known-good sample messages used by several protocol tests."""
from __future__ import annotations

from sharedctl.protocol import messages as m


def heartbeat() -> m.Heartbeat:
    return m.Heartbeat(role="controller", id="ctl-1", seq=7, time=12.5)


def state(**changes) -> m.RobotState:
    fields = dict(
        seq=1, time=2.0, q=(0.1, 0.2, 0.3), qd_hat=(0.0, 0.0, 0.0), q_ref=(0.1, 0.2, 0.3),
        group_classes=(m.SetClass.SAFE, m.SetClass.HAZARD), active_group=1, authority=m.Authority.SHARED,
        k_s=0.0, k_h=0.25, k_f=0.75, u_h=(1.0, 0.0, 0.0), u_f=(0.0, 1.0, 0.0), u_s=(0.25, 0.75, 0.0),
        wheel_torques=(0.5, -0.5, 0.0), theta_hat=(1.0, 2.0, 3.0), min_margin=0.05,
        region_margins=(0.05, 0.4), estop_active=False, lease_holder="alice",
        link=m.LinkHealth(operator_latency_ms=20.0, loss_fraction=0.01, staleness_ms=30.0, can_feedback_age_ms=4.0))
    fields.update(changes)
    return m.RobotState(**fields)


def command(**changes) -> m.OperatorCommand:
    fields = dict(operator_id="alice", session_id="s-1", seq=3, send_time=100.0, joystick=(0.5, -0.5, 0.0),
                  q_d=(1.0, 2.0, 0.5), qd_d=(0.1, 0.0, 0.0), qdd_d=(0.0, 0.0, 0.0), deadman=True,
                  estop=False, control_request=m.ControlRequest.NONE)
    fields.update(changes)
    return m.OperatorCommand(**fields)
