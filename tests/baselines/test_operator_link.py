"""The in-process operator link: rate, delay, loss, hold-last-value and the 0.3 s hands-off."""
import numpy as np
import pytest

from sharedctl.baselines.operator_link import LinkConditions, OperatorLink
from sharedctl.human import AdversarialOperator, LineTrajectory

PERIOD = 0.002


def _operator():
    return AdversarialOperator(LineTrajectory(np.array([0.0, 9.0, 0.0]), np.zeros(3)), np.full(3, 20.0),
                               np.array([0.0, 9.0, 0.0]))


def _inputs(conditions, seconds):
    link = OperatorLink(_operator(), conditions)
    q, v = np.zeros(3), np.zeros(3)
    return link, [link.input_at(k * PERIOD, q, v) for k in range(int(round(seconds / PERIOD)))]


def test_commands_arrive_after_the_uplink_delay_clipped_to_the_wire_range():
    link, out = _inputs(LinkConditions(uplink_delay=0.1), 0.2)
    first_active = next(k for k, (_, off) in enumerate(out) if not off)
    assert first_active * PERIOD == pytest.approx(0.1, abs=1e-9)
    op, _ = out[-1]
    assert np.allclose(op.force, [0.0, 20.0, 0.0])          # deflection 9 m clipped to 1
    assert op.intent == 0.5 * 20.0


def test_a_silent_operator_is_hands_off_after_the_timeout_and_the_wish_is_held():
    link, out = _inputs(LinkConditions(loss=0.95, seed=3), 10.0)
    hands_off = np.array([off for _, off in out])
    assert link.lost > 0.9 * link.sent
    assert hands_off.any() and (~hands_off).any()
    for op, off in out:
        if off:
            assert not np.any(op.force) and op.intent == 0.0 and not np.any(op.desired.q_dot)


def test_losses_follow_the_seed():
    a, _ = _inputs(LinkConditions(loss=0.2, seed=5), 2.0)
    b, _ = _inputs(LinkConditions(loss=0.2, seed=5), 2.0)
    c, _ = _inputs(LinkConditions(loss=0.2, seed=6), 2.0)
    assert a.sent == 100 and a.lost == b.lost
    assert (a.lost, a._rng.random()) != (c.lost, c._rng.random())

