"""What the controller admits beyond the wire's bounds (services/controller/admission.py): a rate per operator
session for commands and lease queries, and the operator's wish within reach of the robot."""
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from sharedctl.protocol.messages import LeaseRequest
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.services.controller import lease_queries
from sharedctl.services.controller.admission import RateLimit, WishBounds
from sharedctl.services.controller.daemon import Mode
from sharedctl.services.controller.lease import OperatorLease
from sharedctl.services.controller.operator_input import OperatorInputPolicy
from sharedctl.services.controller.replay_guard import ReplayGuard

from .test_controller_loop import arm, events, feed, make_daemon
from .test_controller_operator_input import KP, POSE, command, offer


@pytest.mark.parametrize("field, value", [("q_d", (1e308, 3.0, 0.0)), ("q_d", (-0.9, -1e12, 0.0)),
                                          ("q_d", (-0.9, 3.0, 1e6)), ("qd_d", (0.0, 1e300, 0.0)),
                                          ("qdd_d", (-5e3, 0.0, 0.0))])
def test_a_finite_but_absurd_wish_is_refused_and_counted_never_used(field, value):
    """Threat: a desired pose of 1e308 is finite, so the wire accepts it (docs/security.md)."""
    policy = OperatorInputPolicy(KP)
    policy.pose = POSE
    assert offer(policy, command(1), now=10.0)
    bad = replace(command(2), **{field: value})
    assert not offer(policy, bad, now=10.01)
    assert policy.rejections == Counter(out_of_bounds=1) and policy.current.seq == 1
    op, _ = policy.operator_input(10.02, POSE)
    np.testing.assert_allclose(op.desired.q, command(1).q_d)


def test_a_wish_within_reach_passes_the_bounds():
    bounds = WishBounds()
    assert bounds.judge((5.0, 3.0, 3.0), (2.0, -2.0, 6.0), (50.0, 0.0, -50.0), (-0.9, 3.0, 0.0)) is None


def test_the_daemon_drives_on_through_an_absurd_wish_instead_of_stopping():
    """The absurd wish is refused at the door: the current command stays the last admissible one, the loop runs
    on (before, such a wish became the machine's reference whenever the machine took authority)."""
    from .test_controller_loop import operator
    d = make_daemon()
    arm(d)
    operator(d, 1, 10.003, joystick=(0.2, 0.0, 0.0))
    d.policy.offer(encode_message(replace(command(2), operator_id="op", session_id="s", q_d=(1e308, 3.0, 0.0))),
                   10.0035)
    feed(d, 10.004, heartbeat=False)
    d.tick(10.004)
    assert d.mode is Mode.RUNNING and d.policy.rejections["out_of_bounds"] == 1
    assert not any(e.kind.value == "estop" for e in events(d))


def test_a_session_beyond_its_rate_is_refused_and_a_console_never_is():
    policy = OperatorInputPolicy(KP)
    accepted = sum(offer(policy, command(seq, send_time=100.0 + seq * 1e-4), now=10.0 + seq * 1e-4)
                   for seq in range(1, 1001))                  # 10 kHz for 0.1 s
    assert accepted <= 50 + 250 * 0.1 + 1 and policy.rejections["rate_limited"] == 1000 - accepted
    calm = OperatorInputPolicy(KP)
    assert all(offer(calm, command(seq, send_time=100.0 + seq / 50), now=10.0 + seq / 50)
               for seq in range(1, 501))                        # 50 Hz for 10 s
    burst = OperatorInputPolicy(KP)                             # a second of commands released at once
    assert all(offer(burst, command(seq), now=10.0) for seq in range(1, 51))


def test_the_rate_is_per_session_and_the_keys_are_bounded():
    limit = RateLimit(rate=10.0, burst=2, max_keys=3)
    assert [limit.admit("a", 0.0) for _ in range(3)] == [True, True, False]
    assert limit.admit("b", 0.0)                                # another session: its own bucket
    assert limit.admit("a", 0.1)                                # one token back after 0.1 s at 10 Hz
    for k in range(5):
        limit.admit(f"x{k}", 0.2)
    assert len(limit._buckets) == 3 and limit.refused == 1


def test_lease_queries_beyond_their_rate_are_refused_with_a_reason():
    lease, guard, rejections, limit = OperatorLease(), ReplayGuard(), Counter(), RateLimit(10.0, 10)
    replies = [lease_queries.answer(encode_message(LeaseRequest(operator_id="m", session_id="m1", seq=k, time=100.0,
                                                                action="take")),
                                    lease, guard, rejections, 0.001 * k, 100.01, limit) for k in range(1, 101)]
    refused = [r for r in replies if "rate_limited" in r.reason]
    assert len(refused) == rejections["lease_rate_limited"] >= 100 - 10 - 1
