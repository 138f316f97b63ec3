"""The robot's Prometheus collector (services/robot/metrics.py) on a real simulation and process shell, fed
frames on an in-memory bus, read back through prometheus_client's exposition parser."""
from __future__ import annotations

import can
import pytest

from sharedctl.models import OmniRobot
from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.odrive_enums import AxisState, CommandId
from sharedctl.services.lifecycle import RateClock
from sharedctl.services.robot.metrics import RobotCollector
from sharedctl.services.robot.plant import RobotSimConfig
from sharedctl.services.robot.process import RobotProcess
from sharedctl.services.robot.simulation import RobotSimulation

from .test_controller_metrics import scrape, value

P = "sharedctl_robot_"


class MemoryBus:
    """python-can's `recv`/`send`: hands out `incoming`, keeps what was sent."""

    def __init__(self, incoming) -> None:
        self.incoming, self.sent = list(incoming), []

    def recv(self, timeout=None):
        return self.incoming.pop(0) if self.incoming else None

    def send(self, msg, timeout=None):
        self.sent.append(msg)


def message(frame, data: bytes | None = None) -> can.Message:
    f = cs.encode(frame)
    payload = f.data if data is None else data
    return can.Message(arbitration_id=f.arbitration_id, is_extended_id=False, is_remote_frame=f.is_remote,
                       dlc=f.dlc if data is None else len(data), data=None if f.is_remote else payload)


def process_with(frames, **config) -> RobotProcess:
    sim = RobotSimulation(OmniRobot(), RobotSimConfig(**config), [-0.9, 3.0, 0.0], [0.0, 0.0, 0.0])
    return RobotProcess(sim, MemoryBus(frames), None, "unit")


@pytest.fixture
def process():
    frames = [
        message(cs.SetAxisState(0, AxisState.CLOSED_LOOP_CONTROL)),       # armed, then never fed
        message(cs.PollRequest(1, CommandId.GET_BUS_VOLTAGE_CURRENT)),    # answered at once
        message(cs.GetEncoderEstimates(2, 0.0, 0.0)),                     # the drive → host direction: an echo
        message(cs.SetAxisState(5, AxisState.IDLE)),                      # a node this robot has not got
        message(cs.SetInputTorque(0, 1.0), data=b"\x00\x01"),             # Set_Input_Torque needs 8 bytes
    ]
    process = process_with(frames)
    process.receive_pending(0.0)
    for k in range(1, 201):                                               # 0.2 s at 1 kHz: the watchdog trips
        for frame in process.sim.advance(k * 1e-3):
            process.send(frame)
    return process


def test_frames_physics_steps_and_the_loop_clock_are_the_processs_own(process):
    process.clock = RateClock(0.001)
    process.clock.missed, process.truth_seq = 3, 42
    samples, types = scrape(RobotCollector(process))
    assert value(samples, P + "physics_steps_total") == 200
    assert value(samples, P + "simulated_seconds") == pytest.approx(0.2)
    assert value(samples, P + "physics_rate_hertz") == 1000.0
    assert value(samples, P + "missed_ticks_total") == 3
    assert value(samples, P + "truth_messages_total") == 42
    assert value(samples, P + "can_frames_received_total") == 2
    assert value(samples, P + "can_frames_sent_total") == len(process.bus.sent)      # what the bus was handed
    assert value(samples, P + "can_frames_ignored_total", reason="echo") == 1
    assert value(samples, P + "can_frames_ignored_total", reason="other_node") == 1
    assert value(samples, P + "can_decode_errors_total") == 1
    assert types[P + "physics_steps"] == "counter" and types[P + "simulated_seconds"] == "gauge"


def test_a_watchdog_trip_disarms_its_axis_and_engages_its_brake(process):
    samples, _ = scrape(RobotCollector(process))
    assert [value(samples, P + "watchdog_trips_total", axis=a) for a in "012"] == [1, 0, 0]
    assert [value(samples, P + "axis_armed", axis=a) for a in "012"] == [0, 0, 0]
    assert [value(samples, P + "brake_engaged", axis=a) for a in "012"] == [1, 1, 1]


def test_a_robot_without_brakes_reports_none_engaged():
    samples, _ = scrape(RobotCollector(process_with([], brake_torque=0.0)))
    assert [value(samples, P + "brake_engaged", axis=a) for a in "012"] == [0, 0, 0]
    assert value(samples, P + "missed_ticks_total") == 0           # before the loop's clock starts
