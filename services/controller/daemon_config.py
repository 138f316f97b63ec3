"""The controller daemon's configuration (`sharedctl controller`'s options, validated by command.py)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .checkpoint import DEFAULT_INTERVAL as CHECKPOINT_INTERVAL

from .lease import DEFAULT_EXPIRY, LeaseMode
from .replay_guard import DEFAULT_MAX_AGE
from .resume import DEFAULT_MAX_AGE as CHECKPOINT_MAX_AGE
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
    scenario: str = ""                  # the scenario's name (a checkpoint is resumed only by the same scenario)
    pose: str = "checkpoint"            # where the start pose comes from (resume.py): "checkpoint" | "scenario"
    checkpoint: Path | None = None      # the checkpoint file (checkpoint.py); None: none written or read
    checkpoint_interval: float = CHECKPOINT_INTERVAL  # s between checkpoints while running
    checkpoint_max_age: float = CHECKPOINT_MAX_AGE    # s: an older checkpoint is not resumed from
    pose_tolerance: float = 0.01        # m: wheel travel the odometry may have missed before arming is refused
    operators: object = None            # security.signing.TrustList: signed operator traffic only; None: ids as sent
    ros2_domain: int | None = None      # ROS 2 domain of the rmw_zenoh node (ros2_links.py); None: no ROS 2
    twist_scale: object = None          # twist_input.TwistScale: a Twist's full deflection; None: the defaults
