"""The simulated robot without its wires: three ODrive axes on the true plant, and the frame schedule.

Pure logic driven by an explicit time `now` (s since start): `receive` typed frames, `advance`
to a time (watchdogs, RK4 physics steps, cyclic frames due), read `state` for the ground truth.
`process.py` wires this to CAN and Zenoh.
"""
from __future__ import annotations

import math

from sharedctl.models import OmniRobot
from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.canframe import DEFAULT_WHEEL_NODES, MAX_CMD_ID

from ..lifecycle import Schedule
from .axis import Axis, AxisConfig
from .plant import Plant, PlantState, RobotSimConfig

TWO_PI = 2.0 * math.pi
MAX_CATCH_UP_STEPS = 50   # physics steps per advance(); a longer stall is skipped (and counted)

#: command ids of the frames a drive sends (data frames); their echoes on udp_multicast are ignored
ODRIVE_SENT_COMMANDS = frozenset(int(spec.cmd) for spec in cs.FRAME_SPECS.values() if spec.sender == "odrive")


def is_own_direction(arbitration_id: int, is_remote: bool) -> bool:
    """True for a frame of the drive → host direction (what this robot itself sends)."""
    return not is_remote and (arbitration_id & MAX_CMD_ID) in ODRIVE_SENT_COMMANDS


class RobotSimulation:
    """Axes (node ids `nodes`, wheel j ↔ nodes[j]) driving the plant; time in s from start."""

    def __init__(self, model: OmniRobot, config: RobotSimConfig, q0, qd0, nodes=DEFAULT_WHEEL_NODES) -> None:
        self.config = config
        self.plant = Plant(model, config)
        self.state: PlantState = self.plant.initial_state(q0, qd0)
        axis_config = AxisConfig(torque_limit=config.torque_limit, watchdog_timeout=config.watchdog_timeout)
        self.axes = [Axis(node, axis_config) for node in nodes]
        self.by_node = {axis.node_id: axis for axis in self.axes}
        self.dt = 1.0 / config.physics_rate_hz
        self.time = 0.0
        self.steps = 0
        self.skipped_time = 0.0
        self.heartbeat_schedule = Schedule(config.heartbeat_rate_hz)
        self.encoder_schedule = Schedule(config.encoder_rate_hz)
        self.truth_schedule = Schedule(config.truth_rate_hz)
        self.down_until: dict[int, float] = {}   # axis index → when a drive that is restarting is back
        self._update_feedback()

    def restart_drive(self, index: int, down: float, now: float) -> None:
        """Drive `index` loses power at `now`: disarmed (its brake engages), deaf and silent for `down` s, then
        back as a drive that booted (`Axis.restart`: IDLE, no errors, its encoder counting from 0)."""
        axis = self.axes[index]
        axis.power_off()
        self.down_until[index] = now + down

    @property
    def watchdog_trips(self) -> int:
        return sum(axis.watchdog_trips for axis in self.axes)

    def receive(self, frame: object, now: float) -> list:
        """A decoded host → drive frame at time `now`; returns the reply frames (RTR polls)."""
        axis = self.by_node.get(getattr(frame, "node_id", None))
        if axis is None or self.axes.index(axis) in self.down_until:
            return []
        axis.tick(now)  # an expired watchdog trips before a late command can revive it
        return axis.handle(frame, now)

    def applied_torques(self) -> list[float]:
        return [axis.applied_torque() for axis in self.axes]

    def advance(self, now: float) -> list:
        """Run watchdogs and physics up to `now`; return the cyclic frames due (heartbeats, encoders)."""
        for axis in self.axes:
            axis.tick(now)
        steps = 0
        while self.time + self.dt <= now + 1e-9:
            if steps == MAX_CATCH_UP_STEPS:
                self.skipped_time += now - self.time
                self.time = now
                break
            brakes = self.plant.brake_torques([not axis.armed for axis in self.axes])
            self.state = self.plant.step(self.state, self.applied_torques(), self.dt, brakes)
            self.time += self.dt
            self.steps += 1
            steps += 1
            self._update_feedback()
        for index, until in list(self.down_until.items()):
            if now >= until:
                del self.down_until[index]
                self.axes[index].restart(float(self.state.wheel_turns[index]), now)
                self._update_feedback()
        live = [axis for j, axis in enumerate(self.axes) if j not in self.down_until]
        frames = []
        if self.heartbeat_schedule.due(now):
            frames += [axis.heartbeat() for axis in live]
        if self.encoder_schedule.due(now):
            frames += [axis.encoder_estimates() for axis in live]
        return frames

    def truth_due(self, now: float) -> bool:
        return self.truth_schedule.due(now)

    def summary(self) -> dict:
        """How far the simulation got: its time, the physics steps it took and the time it skipped (stalls
        longer than MAX_CATCH_UP_STEPS steps), and the drives' watchdog trips."""
        return {"elapsed_s": self.time, "physics_steps": self.steps, "skipped_s": self.skipped_time,
                "watchdog_trips": self.watchdog_trips}

    def _update_feedback(self) -> None:
        omega = self.plant.wheel_speeds(self.state)
        for j, axis in enumerate(self.axes):
            axis.set_feedback(float(self.state.wheel_turns[j]), omega[j] / TWO_PI)
