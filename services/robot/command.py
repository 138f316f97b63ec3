"""`sharedctl robot` — the simulated robot: true dynamics behind three simulated ODrive axes.

    sharedctl robot [--scenario FILE|NAME] [--can-interface I --can-channel C --can-option k=v ...]
                    [--zenoh-listen EP | --zenoh-connect EP] [--robot-id ID] [--duration S]
                    [--spin-us 100] [--cpu N] [--drive-restart AXIS,DOWN] [--json OUT]
                    [--metrics HOST:PORT [--metrics-allow-remote]]

Speaks CANSimple on the CAN bus (services/can_bus.py picks vcan0 or host-local udp_multicast),
publishes GroundTruth on `sharedctl/v1/<robot>/truth` (100 Hz) and a liveliness token on
`sharedctl/v1/<robot>/alive/robot`. `[robot_sim]` in the scenario overrides the simulation
defaults (see plant.RobotSimConfig). SIGUSR2 restarts drive AXIS of `--drive-restart` (default 1,0.5):
silent for DOWN s, then back IDLE, without errors, its encoder counting from 0 (Axis.restart; the
fault `robot.reboot_at`). SIGINT/SIGTERM: stops within 2 s, exit 0, with a summary line
for people and, with `--json OUT`, the summary as JSON (`summary`): what another module reads.
`--metrics HOST:PORT` serves Prometheus metrics (services/metrics.py, metrics.py; docs/metrics.md).
"""
from __future__ import annotations

import os
import signal
import sys

import zenoh

from sharedctl.models import OmniRobot
from sharedctl.protocol.errors import KeyExprError
from sharedctl.protocol.keys import check_robot_id
from sharedctl.scenario import ScenarioError

from .. import can_bus, metrics as metrics_server, zenoh_session
from ..security import zenoh_config
from ..lifecycle import StopFlag
from ..service_config import add_argument as add_service_config_argument
from ..scenario_files import load
from ..summary_output import write_json
from ..controller.priority import pin_to_cpu
from .plant import RobotSimConfig, RobotSimConfigError
from .process import CpuMeter, RobotProcess
from .simulation import RobotSimulation

PROG = "sharedctl robot"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("robot", help="run the simulated robot (three ODrive axes on CAN, ground truth on Zenoh)")
    p.add_argument("--scenario", default="paper_convex",
                   help="scenario TOML file or packaged name (default: paper_convex): [robot], [initial], [robot_sim]")
    can_bus.add_arguments(p)
    z = p.add_mutually_exclusive_group()
    z.add_argument("--zenoh-listen", metavar="EP",
                   help=f"loopback endpoint to listen on (default: {zenoh_session.DEFAULT_ENDPOINT})")
    z.add_argument("--zenoh-connect", metavar="EP", help="loopback endpoint of a peer to connect to")
    zenoh_config.add_argument(p)
    p.add_argument("--robot-id", default="robot1", help="robot id in the Zenoh keys (default: robot1)")
    p.add_argument("--duration", type=float, metavar="S",
                   help="stop after S seconds (default: run until SIGINT/SIGTERM)")
    p.add_argument("--spin-us", type=float, default=100.0,
                   help="poll the clock for this long before each physics tick instead of sleeping, so the drives "
                        "send on time as a microcontroller's timer would (default 100; 0: plain sleep)")
    p.add_argument("--cpu", type=int, metavar="N", help="run the whole process on CPU N (default: no pinning)")
    p.add_argument("--json", metavar="OUT", help="at exit, write the summary (physics steps, missed ticks, frames, "
                                                 "watchdog trips, …) as JSON to OUT")
    p.add_argument("--drive-restart", default="1,0.5", metavar="AXIS,DOWN",
                   help="what SIGUSR2 does: drive AXIS (0, 1, 2) loses power for DOWN s and comes back as a drive "
                        "that booted (default 1,0.5)")
    metrics_server.add_arguments(p)
    add_service_config_argument(p)
    p.set_defaults(handler=run)


def _fail(text: str, code: int = 2) -> int:
    print(f"{PROG}: {text}", file=sys.stderr)
    return code


def build_simulation(scenario_name: str) -> RobotSimulation:
    """Scenario → simulation (true parameters from [robot], start from [initial], [robot_sim] settings)."""
    scenario = load(scenario_name)
    loop, q0, qd0 = scenario.closed_loop()
    if not isinstance(loop.model, OmniRobot):
        raise ScenarioError("robot.kind must be omni3 for sharedctl robot")
    config = RobotSimConfig.from_table(scenario.data.get("robot_sim"))
    return RobotSimulation(loop.model, config, q0, qd0)


def run(args) -> int:
    stop = StopFlag().install()
    try:
        sim = build_simulation(args.scenario)
        robot_id = check_robot_id(args.robot_id)
        spec = can_bus.spec_from_args(args)
        listen = [args.zenoh_listen] if args.zenoh_listen else []
        connect = [args.zenoh_connect] if args.zenoh_connect else []
        if not listen and not connect and not args.zenoh_config:
            listen = [zenoh_session.DEFAULT_ENDPOINT]
        zenoh_config.check_session_args(args.zenoh_config, listen, connect)  # loopback only
        axis, down = (float(v) for v in args.drive_restart.split(","))
        if axis not in (0.0, 1.0, 2.0) or not down > 0:
            raise ValueError("--drive-restart: AXIS must be 0, 1 or 2 and DOWN positive")
        metrics_address = metrics_server.address_from_args(args)
    except (ScenarioError, RobotSimConfigError, KeyExprError, ValueError) as exc:
        return _fail(str(exc))
    if args.duration is not None and not args.duration > 0:
        return _fail("--duration must be positive")
    if not 0.0 <= args.spin_us * 1e-6 < sim.dt:
        return _fail("--spin-us must be ≥ 0 and shorter than the physics period")
    pinned = ""
    if args.cpu is not None:   # before the bus and the session start their threads: they inherit it
        if args.cpu not in os.sched_getaffinity(0) or not pin_to_cpu(args.cpu):
            return _fail(f"--cpu {args.cpu}: this process may run on CPUs {sorted(os.sched_getaffinity(0))}")
        pinned = f", on CPU {args.cpu}"

    try:
        bus = can_bus.open_transport(spec)
    except Exception as exc:  # noqa: BLE001 — each CAN back-end raises its own types: any of them fails the start
        return _fail(f"cannot open CAN bus {spec.describe()}: {exc}", 1)
    try:
        session = zenoh_config.open_configured(args.zenoh_config, listen, connect)
    except (zenoh.ZError, ValueError) as exc:  # ZError: e.g. the port is taken; ValueError: a bad config
        bus.shutdown()
        return _fail(f"cannot open Zenoh session ({' '.join(listen + connect)}): {exc}", 1)

    cpu = CpuMeter()
    process = exporter = None
    try:
        process = RobotProcess(sim, bus, session, robot_id)
        process.drive_restart = (int(axis), down)
        if metrics_address is not None:
            try:
                exporter = serve_metrics(metrics_address, process)
            except OSError as exc:
                return _fail(f"cannot serve metrics on {args.metrics}: {exc}", 1)
        signal.signal(signal.SIGUSR2, lambda *_: process.request_drive_restart())
        c = sim.config
        endpoint = zenoh_config.describe(args.zenoh_config, listen, connect)
        print(f"{PROG}: {robot_id} on CAN {spec.describe()}, Zenoh {endpoint}; physics {c.physics_rate_hz:g} Hz, "
              f"encoder {c.encoder_rate_hz:g} Hz, heartbeat {c.heartbeat_rate_hz:g} Hz, truth {c.truth_rate_hz:g} Hz, "
              f"watchdog {c.watchdog_timeout:g} s{pinned}", flush=True)
        process.run(stop, args.duration, spin=args.spin_us * 1e-6)
    finally:
        if exporter is not None:
            exporter.close()
        if process is not None:
            process.close()
        session.close()
        bus.shutdown()
    print(f"{PROG}: stopped after {sim.time:.2f} s: {process.summary()}; cpu {100 * cpu.fraction():.0f}% of one core",
          flush=True)
    if args.json:
        try:
            write_json(args.json, {**summary(process, cpu), **({"metrics_url": exporter.url} if exporter else {})})
        except OSError as exc:
            return _fail(f"summary not written to {args.json}: {exc}", 1)
    return 0


def serve_metrics(address, process: RobotProcess):
    """The metrics server (services/metrics.py) with the robot's collector; prints where it listens."""
    from .metrics import RobotCollector      # imports prometheus_client: only with --metrics

    exporter = metrics_server.serve(address, RobotCollector(process))
    print(f"{PROG}: metrics on {exporter.url}", flush=True)
    return exporter


def summary(process: RobotProcess, cpu: CpuMeter) -> dict:
    """The run as a dict, units in the key names: the simulation's figures (`RobotSimulation.summary`), the
    loop's missed physics ticks, the CAN frames and GroundTruth messages, the process's CPU."""
    counts = process.counts
    return {**process.sim.summary(), "missed_ticks": counts["missed_ticks"],
            "frames_in": counts["frames_in"], "frames_out": counts["frames_out"], "bad_frames": counts["bad_frames"],
            "echoes_skipped": counts["echoes"], "other_nodes": counts["other_nodes"],
            "error_frames": counts["error_frames"], "send_errors": counts["send_errors"],
            "truth_messages": process.truth_seq, "drive_restarts": sum(a.restarts for a in process.sim.axes),
            "cpu_percent": 100.0 * cpu.fraction()}
