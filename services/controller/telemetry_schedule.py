"""What the controller publishes on its loop's clock, after each period's torque frames: a RobotState
at the telemetry rate and a Heartbeat message once a second.

Both rates are kept on the clock (`lifecycle.Schedule`), not counted in ticks: a loop that misses
deadlines still reports at them. A RobotState is captured, built and sent in three consecutive
periods (`stage`): at once they took 0.5–0.65 ms of the loop thread in one period, against ≈ 0.6 ms
for a whole ordinary period; spread, no period carries much more than another (docs/performance.md).
At a telemetry rate above a third of the loop's, each goes out whole in the period it is due.

`followers` (the ROS 2 node's Odometry and authority, ros2_links.py) take the RobotState just sent, each in
a period of its own after the three; as with the stages, if they do not all fit in a telemetry period
everything goes out at once.
"""
from __future__ import annotations

import time

from sharedctl.protocol.messages import Heartbeat
from sharedctl.protocol.msgpack_codec import encode_message

from ..lifecycle import Schedule
from .telemetry import robot_state

TELEMETRY_STAGES = 3        # a RobotState is captured, built and sent in three consecutive periods


class TelemetrySchedule:
    """RobotState (`capture(now)` → `telemetry.robot_state`'s arguments of this period) on `state_pub` at
    `rate`, a Heartbeat of (`role`, `robot_id`) on `alive_pub` at 1 Hz; `failed(now, text)` hears of a
    RobotState that could not be sent; each of `followers` (`follower(state, now)`) gets every RobotState
    sent, in a period of its own."""

    def __init__(self, rate: float, period: float, capture, state_pub, alive_pub, dims, role: str, robot_id: str,
                 failed, followers=()) -> None:
        self.state_schedule, self.heartbeat_schedule = Schedule(rate), Schedule(1.0)
        self.period = period
        self.capture, self.failed = capture, failed
        self.state_pub, self.alive_pub = state_pub, alive_pub
        self.dims, self.role, self.robot_id = dims, role, robot_id
        self.heartbeat_seq = 0
        self.followers = tuple(followers)
        self.stages = TELEMETRY_STAGES + len(self.followers)
        self._capture: tuple | None = None      # a RobotState between its stages
        self._message = None
        self._sent = None                       # the RobotState sent, for the followers
        self._stage: int | None = None          # the stage the next period runs, None: none under way

    def publish_due(self, now: float) -> None:
        """Once a period, after the torque frames: the RobotState stage and the Heartbeat that are due."""
        self.states(now)
        self.heartbeats(now)

    def states(self, now: float) -> None:
        """The RobotState stage of this period: the first when one is due, else the next of one under way."""
        if self._stage is None:
            if not self.state_schedule.due(now):
                return
            if self.stages * self.period > self.state_schedule.period:
                self.publish_state(now)
                return
            self._stage = 0
        stage = self._stage
        self._stage = stage + 1 if stage + 1 < self.stages else None
        self.stage(stage, now)

    def heartbeats(self, now: float) -> None:
        """A Heartbeat message once a second on the clock (the daemon sends the first before its clock starts)."""
        if self.heartbeat_schedule.due(now):
            self.heartbeat_seq += 1
            try:
                self.alive_pub.put(encode_message(Heartbeat(self.role, self.robot_id, self.heartbeat_seq, time.time())))
            except Exception:  # noqa: BLE001 — a heartbeat not sent is the next one's business, never the loop's
                pass

    def publish_state(self, now: float) -> None:
        """One RobotState of this period, captured, built, encoded and put at once (and its followers)."""
        for stage in range(self.stages):
            self.stage(stage, now)

    def stage(self, stage: int, now: float) -> None:
        """One of a RobotState's stages: 0 captures this period's values (and works out the reference q_r,
        on demand), 1 builds the message, 2 encodes and puts it. The message is the capture's (its seq and
        time): the values are never mutated after their period (each tick makes new arrays), so building
        it later changes nothing but the CPU's timing. Stages 3, 4, … hand the message sent to the followers."""
        try:
            if stage == 0:
                self._message = self._sent = None
                self._capture = self.capture(now)
            elif stage == 1 and self._capture is not None:
                capture, self._capture = self._capture, None
                self._message = robot_state(*capture)
            elif stage == 2 and self._message is not None:
                message, self._message = self._message, None
                self.state_pub.put(encode_message(message, self.dims))
                self._sent = message if self.followers else None
            elif stage > 2 and self._sent is not None:
                message = self._sent
                if stage + 1 == self.stages:
                    self._sent = None
                self.followers[stage - TELEMETRY_STAGES](message, now)
        except Exception as exc:  # noqa: BLE001 — telemetry must not stop the loop
            what = ("RobotState" if stage < TELEMETRY_STAGES
                    else getattr(self.followers[stage - TELEMETRY_STAGES], "__name__", "a follower's message"))
            self._capture = self._message = None
            self.failed(now, f"{what} not sent: {type(exc).__name__}: {exc}")
