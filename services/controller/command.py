"""`sharedctl controller`: the controller/arbiter daemon (docs/services.md).

    sharedctl controller [--scenario FILE|name] [--controller ce|nce|of]
                         [--can-interface I --can-channel C --can-option k=v …]
                         [--zenoh-listen EP]… [--zenoh-connect EP]… [--robot-id ID]
                         [--rate 500] [--telemetry-rate 50] [--torque-limit 60] [--duration S]
                         [--feedback-timeout-ms 50] [--priority realtime|high|normal] [--quiet]
                         [--[no-]sensor-sync] [--sensor-lead-us 250] [--sensor-wait-us T/4] [--spin-us 100]
                         [--torque-at-us 0] [--cpu N] [--[no-]predict] [--rtt-probe-rate 10]
                         [--lease implicit|explicit] [--lease-expiry-ms 1000] [--max-command-age-ms 500]
                         [--max-clock-skew-ms MS] [--pose checkpoint|scenario] [--checkpoint FILE|none]
                         [--checkpoint-max-age-s 60] [--operators FILE] [--json OUT]
                         [--metrics HOST:PORT [--metrics-allow-remote]]
                         [--ros2 [DOMAIN] [--twist-max-linear 0.5] [--twist-max-angular 1.0]]

Start (resume.py): the controller first disarms every drive and hears each one idle. With `--pose
checkpoint` (the default) a controller that follows one that failed resumes from its checkpoint (the
pose carried forward over the wheel encoders' increments since) and keeps the drives disarmed until
an operator takes control; with no checkpoint, or the last controller stopped on purpose, it starts
at the scenario's pose — unless the drives report errors, which say a controller was driving them:
then arming is refused, and why is said. `--pose scenario` declares the robot at the scenario's
start pose (a first start, a re-homing).

With `--operators FILE` (services/security/signing.py) only signed operator traffic counts: a command or a
lease request needs a valid Ed25519 signature by an operator the file trusts for this robot, and must name
that operator; the lease is then held by a verified identity (docs/security.md).

With `--ros2 [DOMAIN]` (the `ros2` extra) it is also a ROS 2 node over rmw_zenoh, `/ROBOT/sharedctl_controller`
in ROS domain DOMAIN (default 0): `/ROBOT/odom` (nav_msgs/msg/Odometry) and `/ROBOT/authority`
(std_msgs/msg/String) out at the telemetry rate, `/ROBOT/cmd_vel` (geometry_msgs/msg/Twist) in as operator
input under the same lease, replay guard, staleness and identity rules as a console's commands
(ros2_links.py, twist_input.py, docs/ros2.md).

At exit it prints a summary line for people and, with `--json OUT`, writes the loop statistics'
summary as JSON (loop_stats.py: units in the key names) — what another module reads. `--metrics HOST:PORT`
serves the same counters, live, as Prometheus metrics (services/metrics.py, metrics.py; docs/metrics.md):
the server's thread is started before the loop thread is pinned, so with `--cpu N` it runs off the loop's
CPU, and with `--priority realtime` it runs SCHED_FIFO below the loop (priority.py).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from sharedctl.protocol import rmw_zenoh
from sharedctl.protocol.keys import check_robot_id
from sharedctl.protocol.errors import KeyExprError
from sharedctl.scenario import ScenarioError

from .. import can_bus, metrics as metrics_server, zenoh_session
from ..security import zenoh_config
from ..security.signing import TrustList
from ..lifecycle import StopFlag
from ..service_config import add_argument as add_service_config_argument
from ..scenario_files import load
from ..summary_output import write_json
from .daemon import MAX_DELAY, ControllerDaemon
from .daemon_config import DaemonConfig
from . import loop_stats
from .priority import HELPER_PRIORITY, LEVELS, keep_off_cpu, make_loop_realtime, make_thread_realtime, pin_to_cpu, \
    raise_nice
from .round_trip import DEFAULT_RATE
from .twist_input import DEFAULT_MAX_ANGULAR, DEFAULT_MAX_LINEAR, TwistScale
from . import checkpoint as checkpoints
from .resume import DEFAULT_MAX_AGE as CHECKPOINT_MAX_AGE, POSE_SOURCES
from ..recording.launch import add_argument as add_record_argument, open_process_recording, summary_line

MAX_PROBE_RATE = 50.0   # Hz: round-trip polls are a few frames a second, never a load on the bus

PROG = "sharedctl controller"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("controller", help="run the controller/arbiter daemon (CAN master + shared controller)")
    p.add_argument("--scenario", default="paper_convex",
                   help="scenario TOML file or packaged name (default: paper_convex)")
    p.add_argument("--controller", choices=("ce", "nce", "of"), help="machine law (default: the scenario's, else ce)")
    can_bus.add_arguments(p)
    add_record_argument(p)
    p.add_argument("--zenoh-listen", metavar="EP", action="append",
                   help=f"listen on this loopback endpoint (repeatable; default {zenoh_session.DEFAULT_ENDPOINT} "
                        "unless --zenoh-connect is given)")
    p.add_argument("--zenoh-connect", metavar="EP", action="append",
                   help="connect to a peer listening on this loopback endpoint (repeatable; peers do not forward "
                        "for each other: connect to every peer whose data you need, or let them connect to you)")
    zenoh_config.add_argument(p)
    p.add_argument("--robot-id", default="robot1", help="robot id in the key expressions (default robot1)")
    p.add_argument("--rate", type=float, default=500.0, help="control loop rate, Hz (default 500)")
    p.add_argument("--telemetry-rate", type=float, default=50.0, help="RobotState rate, Hz (default 50)")
    p.add_argument("--torque-limit", type=float, default=60.0, help="wheel torque limit, N·m (default 60)")
    p.add_argument("--feedback-timeout-ms", type=float, default=50.0,
                   help="CAN feedback age that triggers Estop (default 50)")
    p.add_argument("--duration", type=float, help="stop after this many seconds (default: run until SIGINT/SIGTERM)")
    p.add_argument("--priority", choices=LEVELS, default="realtime",
                   help="scheduling: realtime = nice -10 and SCHED_FIFO 20 for the loop thread (default; falls back "
                        "when not permitted), high = nice -10 only, normal")
    p.add_argument("--quiet", action="store_true", help="no warnings on stderr (events are still published)")
    p.add_argument("--sensor-sync", action=argparse.BooleanOptionalAction, default=True,
                   help="lock the tick phase to the wheel estimates' arrival (default; lower sensor → torque latency; "
                        "phase.py); --no-sensor-sync: free-running ticks")
    p.add_argument("--sensor-lead-us", type=float, default=250.0,
                   help="with --sensor-sync: start each tick this long after the wheel estimates arrive (default 250: "
                        "above the drives' send jitter, so a tick rarely starts before its estimates)")
    p.add_argument("--spin-us", type=float, default=100.0,
                   help="poll the clock for this long before each deadline instead of sleeping (default 100; "
                        "0: plain sleep; costs at most this much CPU per tick)")
    p.add_argument("--torque-at-us", type=float, default=0.0,
                   help="send each tick's torque frames this long after its deadline, or at once if the tick is still "
                        "computing then (time-triggered output: the same actuation delay every period; 0, the "
                        "default: as soon as computed — delay costs the shared controller margin on a loaded host; "
                        "the hold polls the clock, never sleeps)")
    p.add_argument("--predict", action=argparse.BooleanOptionalAction, default=True,
                   help="run each control step on the state predicted for when its torques act: the oldest wheel "
                        "estimate's age + the measured CAN round trip (+ the --torque-at-us hold), at most "
                        f"{MAX_DELAY * 1e3:g} ms and 64 periods (default; docs/control.md §10); --no-predict: on the "
                        "state as read")
    p.add_argument("--rtt-probe-rate", type=float, default=DEFAULT_RATE, metavar="HZ",
                   help="poll one drive at a time for Get_Bus_Voltage_Current (RTR) this often to measure the CAN "
                        f"round trip (default {DEFAULT_RATE:g}; one frame out and one back per poll; at most "
                        f"{MAX_PROBE_RATE:g}; 0: none, and the round trip counts as 0)")
    p.add_argument("--cpu", type=int, metavar="N",
                   help="run the loop thread on CPU N alone and keep the process's other threads (Zenoh, CAN) off it "
                        "(default: no pinning; docs/performance.md)")
    p.add_argument("--sensor-wait-us", type=float,
                   help="with --sensor-sync: a tick whose period's wheel estimates have not all arrived waits up to "
                        "this long for them (default: a quarter of the period, 500 at 500 Hz; 0: never wait)")
    p.add_argument("--lease", choices=("implicit", "explicit"), default="implicit",
                   help="operator authority lease: implicit = a command while nobody holds control takes it "
                        "(default); explicit = only a take on the lease queryable (or in-band) grants control")
    p.add_argument("--lease-expiry-ms", type=float, default=1000.0,
                   help="the lease is free again after this long without a command or take from its holder "
                        "(default 1000)")
    p.add_argument("--max-command-age-ms", type=float, default=500.0,
                   help="drop operator messages arriving this much later than the session's best delivery "
                        "(default 500)")
    p.add_argument("--max-clock-skew-ms", type=float,
                   help="drop operator messages whose |receive wall time - send_time| exceeds this (only for hosts "
                        "synchronised by chrony/PTP; default: no absolute bound)")
    p.add_argument("--pose", choices=POSE_SOURCES, default="checkpoint",
                   help="where the start pose comes from: checkpoint = resume from the checkpoint of a controller "
                        "that failed (drives disarmed until an operator takes control), else the scenario's start "
                        "pose if the drives report no errors (default); scenario = the robot stands at the "
                        "scenario's start pose (first start, re-homing)")
    p.add_argument("--checkpoint", metavar="FILE",
                   help="the checkpoint file, written every 50 ms and at every Estop (default "
                        "$SHAREDCTL_STATE_DIR, else $XDG_STATE_HOME/sharedctl, else ~/.local/state/sharedctl: "
                        "controller-ROBOT.checkpoint); none: no checkpoint (a restart cannot resume)")
    p.add_argument("--checkpoint-max-age-s", type=float, default=CHECKPOINT_MAX_AGE,
                   help=f"an older checkpoint is not resumed from: arming is refused (default {CHECKPOINT_MAX_AGE:g})")
    p.add_argument("--operators", metavar="FILE",
                   help="the operators file (TOML, written by `sharedctl credentials`): only operator commands and "
                        "lease requests signed by an operator it trusts for this robot, naming that operator, are "
                        "accepted; the lease is bound to the verified operator (docs/security.md). Default: none, "
                        "the operator id is what a command says (a single-operator bench)")
    p.add_argument("--json", metavar="OUT",
                   help="at exit, write the summary (ticks, missed deadlines, jitter, compute and CPU per period, CAN "
                        "frames, operator commands, …; loop_stats.py) as JSON to OUT")
    metrics_server.add_arguments(p)
    p.add_argument("--ros2", type=int, nargs="?", const=0, metavar="DOMAIN",
                   help="also be a ROS 2 (Jazzy) node over rmw_zenoh in this ROS domain (default 0 when given "
                        "without a value): /ROBOT/odom and /ROBOT/authority out, /ROBOT/cmd_vel in as operator input "
                        "(docs/ros2.md; needs the 'ros2' extra). Default: no ROS 2")
    p.add_argument("--twist-max-linear", type=float, default=DEFAULT_MAX_LINEAR, metavar="M_S",
                   help="with --ros2: the linear speed of a Twist that is a full joystick deflection (default "
                        f"{DEFAULT_MAX_LINEAR:g}; faster is full deflection)")
    p.add_argument("--twist-max-angular", type=float, default=DEFAULT_MAX_ANGULAR, metavar="RAD_S",
                   help="with --ros2: the yaw rate of a Twist that is a full joystick deflection (default "
                        f"{DEFAULT_MAX_ANGULAR:g})")
    add_service_config_argument(p)
    p.set_defaults(handler=run)


def run(args) -> int:
    stop = StopFlag().install()
    try:
        robot_id = check_robot_id(args.robot_id)
        if not (args.rate > 0 and args.telemetry_rate > 0 and args.torque_limit > 0 and args.feedback_timeout_ms > 0):
            raise ValueError("--rate, --telemetry-rate, --torque-limit and --feedback-timeout-ms must be positive")
        if not all(0.0 <= value < 1e6 / args.rate for value in (args.spin_us, args.sensor_lead_us, args.torque_at_us)):
            raise ValueError("--spin-us, --sensor-lead-us and --torque-at-us must be ≥ 0 and shorter than the "
                             "control period")
        if not 0.0 <= args.rtt_probe_rate <= MAX_PROBE_RATE:
            raise ValueError(f"--rtt-probe-rate must be between 0 (no polls) and {MAX_PROBE_RATE:g} Hz")
        if args.sensor_wait_us is None:
            args.sensor_wait_us = 0.25e6 / args.rate
        if not 0.0 <= args.sensor_wait_us < 0.5e6 / args.rate:
            raise ValueError("--sensor-wait-us must be ≥ 0 and shorter than half the control period")
        if args.cpu is not None and args.cpu not in os.sched_getaffinity(0):
            raise ValueError(f"--cpu {args.cpu}: this process may run on CPUs {sorted(os.sched_getaffinity(0))}")
        if not (args.lease_expiry_ms > 0 and args.max_command_age_ms > 0
                and (args.max_clock_skew_ms is None or args.max_clock_skew_ms > 0)):
            raise ValueError("--lease-expiry-ms, --max-command-age-ms and --max-clock-skew-ms must be positive")
        if not args.checkpoint_max_age_s > 0:
            raise ValueError("--checkpoint-max-age-s must be positive")
        checkpoint = (None if args.checkpoint == "none"
                      else checkpoints.default_path(robot_id) if args.checkpoint is None else Path(args.checkpoint))
        if checkpoint is not None:
            checkpoint.parent.mkdir(parents=True, exist_ok=True)
        operators = TrustList.from_file(args.operators) if args.operators else None
        metrics_address = metrics_server.address_from_args(args)
        twist_scale = None
        if args.ros2 is not None:
            rmw_zenoh.check_domain(args.ros2)
            rmw_zenoh.check_token(robot_id, "--robot-id with --ros2 (a ROS 2 namespace)")
            twist_scale = TwistScale(args.twist_max_linear, args.twist_max_angular)
        scenario = load(args.scenario)
        loop, q0, _ = scenario.closed_loop(args.controller)
        spec = can_bus.spec_from_args(args)
        connect = list(args.zenoh_connect or [])
        listen = list(args.zenoh_listen or ([] if connect or args.zenoh_config else [zenoh_session.DEFAULT_ENDPOINT]))
        zenoh_config.check_session_args(args.zenoh_config, listen, connect)   # validates before anything opens
    except (ScenarioError, KeyExprError, ValueError, OSError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    config = DaemonConfig(
        robot_id=robot_id, rate=args.rate, telemetry_rate=args.telemetry_rate, torque_limit=args.torque_limit,
        feedback_timeout=args.feedback_timeout_ms / 1e3, duration=args.duration, verbose=not args.quiet,
        realtime=args.priority == "realtime", sensor_sync=args.sensor_sync, sensor_lead=args.sensor_lead_us / 1e6,
        sensor_wait=args.sensor_wait_us / 1e6,
        spin=args.spin_us / 1e6, torque_at=args.torque_at_us / 1e6,
        predict=args.predict, rtt_probe_rate=args.rtt_probe_rate,
        lease_mode=args.lease, lease_expiry=args.lease_expiry_ms / 1e3,
        max_command_age=args.max_command_age_ms / 1e3,
        max_clock_skew=None if args.max_clock_skew_ms is None else args.max_clock_skew_ms / 1e3,
        scenario=scenario.name, pose=args.pose, checkpoint=checkpoint, checkpoint_max_age=args.checkpoint_max_age_s,
        operators=operators, ros2_domain=args.ros2, twist_scale=twist_scale,
    )
    bus = session = daemon = recording = exporter = None
    priority = raise_nice(args.priority)   # before Zenoh and CAN start their threads (they inherit it)
    if args.cpu is not None:
        priority += f", loop on CPU {args.cpu}, {keep_off_cpu(args.cpu)}"   # likewise inherited
    try:
        bus = can_bus.open_transport(spec)
        session = zenoh_config.open_configured(args.zenoh_config, listen, connect)
        recording = open_process_recording(args.record, "controller", robot_id, args.scenario, scenario.name,
                                           session, spec)   # --record DIR: docs/recording.md
        daemon = ControllerDaemon(config, loop, q0, bus, session)
        if metrics_address is not None:   # its thread inherits this one's priority and CPUs: before they change
            exporter = serve_metrics(metrics_address, daemon, loop.controller.name, config.realtime)
        daemon.realtime = config.realtime and make_loop_realtime()   # this thread runs the loop
        if args.cpu is not None and not pin_to_cpu(args.cpu):
            priority += f" (not pinned to CPU {args.cpu})"
        zenoh_desc = zenoh_config.describe(args.zenoh_config, listen, connect)
        print(
            f"{PROG}: robot {robot_id}, scenario {scenario.name}, controller {loop.controller.name}, "
            f"{config.rate:g} Hz (telemetry {config.telemetry_rate:g} Hz), torque limit {config.torque_limit:g} N·m, "
            f"CAN {spec.describe()}, Zenoh {zenoh_desc}, priority {priority}, pose from {args.pose} "
            f"(checkpoint {checkpoint or 'none'})"
            f"{'' if daemon.ros2 is None else f', ROS 2 node {daemon.ros2.node} in domain {args.ros2}'}"
            f"{' + SCHED_FIFO loop' if daemon.realtime else ''}",
            flush=True,
        )
        summary = daemon.run(stop)
        if exporter is not None:
            summary["metrics_url"] = exporter.url
        print(loop_stats.summary_line(summary), flush=True)
        if args.json:
            write_json(args.json, summary)
        return 0
    except Exception as exc:  # noqa: BLE001 — report, clean up, non-zero exit
        print(f"{PROG}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    finally:
        if exporter is not None:
            exporter.close()
        if daemon is not None:
            daemon.links.undeclare()
            if daemon.ros2 is not None:
                daemon.ros2.undeclare()
        if recording is not None:
            print(summary_line(recording.close()), flush=True)
        if session is not None:
            session.close()
        if bus is not None:
            bus.shutdown()


def serve_metrics(address, daemon: ControllerDaemon, law: str, realtime: bool):
    """The metrics server (services/metrics.py) with the controller's collector, its thread SCHED_FIFO below the
    loop when the loop is real-time (priority.py); prints where it listens."""
    from .metrics import ControllerCollector      # imports prometheus_client: only with --metrics

    exporter = metrics_server.serve(address, ControllerCollector(daemon, law),
                                    thread_setup=make_thread_realtime if realtime else None)
    fifo = f" (SCHED_FIFO {HELPER_PRIORITY})" if exporter.setup_result else ""
    print(f"{PROG}: metrics on {exporter.url}{fifo}", flush=True)
    return exporter
