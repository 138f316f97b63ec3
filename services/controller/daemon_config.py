"""The controller daemon's configuration (`sharedctl controller`'s options, validated by command.py)."""
from __future__ import annotations

from dataclasses import dataclass

from .lease import DEFAULT_EXPIRY, LeaseMode
from .replay_guard import DEFAULT_MAX_AGE
from .round_trip import DEFAULT_RATE


@dataclass
class DaemonConfig:
    robot_id: str = "robot1"
    rate: float = 500.0                 # Hz, control loop
    telemetry_rate: float = 50.0        # Hz, RobotState
    torque_limit: float = 60.0          # N·m per wheel (the simulated drive's limit)
    feedback_timeout: float = 0.05      # s: wheel feedback older than this (once armed) → estop
    operator_timeout: float = 0.3       # s: operator silence → hands-off
    arm_timeout: float = 0.5            # s per arming attempt
    duration: float | None = None       # s; None: until SIGINT/SIGTERM
    event_interval: float = 1.0         # s between events of one topic
    verbose: bool = True                # warnings and errors to stderr
    realtime: bool = False              # the loop thread asks for SCHED_FIFO (priority.py)
    sensor_sync: bool = True            # lock the tick phase to the wheel estimates' arrival (phase.py)
    sensor_lead: float = 2.5e-4         # s after the estimates' arrival at which a synchronised tick starts
    sensor_wait: float = 5e-4           # s a synchronised tick waits, at most, for its period's estimates (0: never)
    spin: float = 1e-4                  # s before each deadline polled instead of slept (lifecycle.RateClock)
    torque_at: float = 0.0              # s after its deadline at which a tick sends its torques (0: once computed)
    predict: bool = True                # the step predicts the state for when its torques act (daemon.prediction_delay)
    rtt_probe_rate: float = DEFAULT_RATE  # Hz, CAN round-trip polls (round_trip.py; 0: none, the round trip counts 0)
    lease_mode: str = LeaseMode.IMPLICIT  # implicit: a command takes a free lease; explicit: only a take (lease.py)
    lease_expiry: float = DEFAULT_EXPIRY  # s without commands/takes from the holder → lease free
    max_command_age: float = DEFAULT_MAX_AGE  # s later than the session's best delivery → stale (replay_guard.py)
    max_clock_skew: float | None = None   # s, |receive wall − send_time| bound; None: hosts not synchronised
