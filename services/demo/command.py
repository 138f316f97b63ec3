"""`sharedctl demo [--scenario FILE|name] [--controller ce|nce|of] [--duration S] [--headless] [--json OUT]
[--zenoh-listen ENDPOINT] [--foxglove HOST:PORT] [--ros2 [DOMAIN]]` — the whole system on this host, measured on
the ground truth.

Starts `sharedctl robot`, `sharedctl controller` and `sharedctl console --script SCENARIO` as
child processes (headless, or the live dashboard when a terminal is attached), lets the
scripted operator drive for the scenario's duration, stops them in order (operator,
controller, robot: SIGTERM, then at most 2 s each; SIGKILL only as a last resort and only to
its own children; between the operator and the controller it waits, at most 3 s, for the
robot to come to rest: a controller that exits leaves the wheels unpowered and a moving robot
would coast on), and prints a summary: violations, min_margin and final_speed from
GroundTruth; tracking and authority (the names of `sharedctl sim --json`) from RobotState;
and the in-process sampled simulation of the same scenario (`reference`, computed when the run
is over, by two children: reference_job.py) with the deviation between the two.
Exit 0 only if nothing was violated, no emergency stop cut the run short, and every child exited
cleanly. Robot and controller write their exit summaries as JSON in the log
directory (`--json`); the demo's own JSON holds them, under `processes.<name>.summary`.

Wiring (Zenoh peers do not forward between peers they connect, so the operator console
connects to the controller, whose telemetry it needs):

    robot       listens  tcp/127.0.0.1:R      (GroundTruth)
    controller  listens  tcp/127.0.0.1:C      (--zenoh-listen; RobotState, Events, OperatorCommand)
    console     connects to C
    demo        connects to R and C
    foxglove    (--foxglove) connects to R and C, listens on tcp/127.0.0.1:F; the console also connects to F
    CAN         python-can udp_multicast, host-local (hop_limit=0), a free port per run

With `--ros2 [DOMAIN]` the controller is also a ROS 2 node over rmw_zenoh (docs/ros2.md): a ROS 2
machine reaches it on the controller's endpoint (`--zenoh-listen`).

The run's clock: t = 0 is the instant the controller granted the operator the lease, as it
reports it in every RobotState (`lease_since`); the demo learns it with the first RobotState
that names a holder, one telemetry period or more later, and arms the faults then (the console
starts its script on its first RobotState and takes the lease with its first command). Timed
faults fire on that clock (services/faults/stack.py) and the JSON's `fault_states` hold the
ground truth and the reported torques around the instant each actually fired, and around each
emergency stop (measure.states_at), for the fault campaign's forecasts.
"""
from __future__ import annotations

import importlib.util
import shutil
import sys
import tempfile
import time
from pathlib import Path

from sharedctl.protocol import keys
from sharedctl.scenario import ScenarioError
from sharedctl.services import can_bus

from sharedctl.services.children import (Child, free_udp_port, raise_priority, start_child, udp_receive_buffer_errors,
                                         wait_listening)
from sharedctl.services.foxglove.address import listen_address
from sharedctl.services.faults.stack import ESTOP_OPERATOR, FaultStack, add_arguments as add_fault_arguments
from sharedctl.services.security.secure_stack import OPERATOR, SecureStack, add_arguments as add_secure_arguments
from sharedctl.services.recording.launch import add_argument as add_record_argument, open_demo_recording
from .measure import TOLERANCE, Recorder, deviation, measure, states_at
from .reference_job import ReferenceJob
from sharedctl.services.lifecycle import StopFlag
from sharedctl.services.scenario_files import load
from sharedctl.services.summary_output import emit, read_json
from sharedctl.services.zenoh_session import EndpointError, check_loopback, free_loopback_port, open_session

STARTUP_TIMEOUT = 30.0    # s until the operator is in control
SETTLE_SPEED = 0.02       # m/s: the robot is at rest (the controller is stopped only then)
SETTLE_TIMEOUT = 3.0      # s the controller gets to bring the robot to rest once the operator has let go


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("demo", help="run robot, controller and scripted operator together and measure the run")
    p.add_argument("--scenario", default="paper_convex",
                   help="scenario TOML file or packaged name (default paper_convex)")
    p.add_argument("--controller", choices=("ce", "nce", "of"), help="machine law (default: the scenario's, else ce)")
    p.add_argument("--duration", type=float, metavar="S", help="run length (default: the scenario's duration)")
    p.add_argument("--headless", action="store_true", help="no live dashboard even with a terminal")
    p.add_argument("--json", metavar="OUT", help="write the summary as JSON to OUT ('-' for stdout)")
    p.add_argument("--zenoh-listen", metavar="ENDPOINT",
                   help="the controller's endpoint, with --secure the router's (default: a free loopback port)")
    p.add_argument("--robot-id", default="robot1", help="robot id in the key expressions (default robot1)")
    p.add_argument("--feedback-timeout-ms", type=float, metavar="MS",
                   help="passed to the controller: CAN feedback age that triggers Estop "
                        "(default: the controller's, 50)")
    p.add_argument("--no-reference", action="store_true", help="skip the in-process sampled reference run")
    p.add_argument("--ros2", type=int, nargs="?", const=0, metavar="DOMAIN",
                   help="passed to the controller: also a ROS 2 node over rmw_zenoh in this ROS domain (default 0 "
                        "when given without a value; docs/ros2.md; needs the 'ros2' extra)")
    p.add_argument("--log-dir", metavar="DIR",
                   help="keep the children's output here (default: a temporary directory, removed on success)")
    p.add_argument("--foxglove", metavar="HOST:PORT",
                   help="serve a live view to Foxglove on this loopback WebSocket address (`sharedctl foxglove` as a "
                        "child; needs the 'foxglove' extra; docs/foxglove.md)")
    can_bus.add_arguments(p, "host-local udp_multicast on a free port of its own, so that demos never share a bus; "
                             "give the robot's and the controller's bus to join it from outside")
    add_fault_arguments(p)
    add_record_argument(p)
    add_secure_arguments(p)
    p.set_defaults(handler=run)



# ----- the command -------------------------------------------------------------
def bus_arguments(args, faults: FaultStack) -> tuple[list[str], can_bus.BusSpec]:
    """The CAN arguments of the robot and the controller, and their bus: the one given (`--can-interface/
    --can-channel/--can-option`), else host-local udp_multicast on a free port. `can.*` link faults put a
    gateway between two udp_multicast buses of their own, so they take no bus from outside."""
    given = args.can_interface is not None or args.can_channel is not None or args.can_option
    if given and faults.plan.has("can"):
        raise ValueError("can.* faults put a gateway between two buses of their own: they cannot be combined "
                         "with --can-interface/--can-channel/--can-option")
    if not given:
        port = free_udp_port()
        return (["--can-interface", "udp_multicast", "--can-option", f"port={port}"],
                can_bus.resolve("udp_multicast", None, {"port": port}))
    spec = can_bus.spec_from_args(args)                            # validates: a channel where one is needed
    argv = (["--can-interface", args.can_interface] if args.can_interface else []) + (
        ["--can-channel", args.can_channel] if args.can_channel else [])
    return argv + [a for option in args.can_option or [] for a in ("--can-option", option)], spec


def run(args) -> int:
    stop = StopFlag().install()
    try:
        scenario = load(args.scenario)
        loop, _, _ = scenario.closed_loop(args.controller)
        faults = FaultStack.from_args(args)   # --fault SPEC: see services/faults/stack.py
        secure = SecureStack.from_args(args, free_loopback_port, faults)   # --secure: services/security/secure_stack.py
        controller_ep = (check_loopback(args.zenoh_listen) if args.zenoh_listen and not secure.enabled
                         else f"tcp/127.0.0.1:{free_loopback_port()}")
        keys.check_robot_id(args.robot_id)
        can, faults.bus = bus_arguments(args, faults)
        faults.router = secure if secure.enabled else None
        viewer = _check_foxglove(args.foxglove, secure.enabled)
    except (ScenarioError, EndpointError, ValueError) as exc:
        print(f"sharedctl demo: {exc}", file=sys.stderr)
        return 2
    duration = args.duration or scenario.duration
    if duration <= 0:
        print("sharedctl demo: --duration must be positive", file=sys.stderr)
        return 2
    robot_ep = f"tcp/127.0.0.1:{free_loopback_port()}"
    can_controller, can_robot = faults.can_arguments(can, free_udp_port)
    console_ep = faults.console_endpoint(controller_ep, free_loopback_port)
    interactive = not args.headless and sys.stdin.isatty() and sys.stdout.isatty()
    scenario_arg = str(Path(args.scenario).resolve()) if Path(args.scenario).exists() else args.scenario
    backstop = str(duration + STARTUP_TIMEOUT + 30.0)    # children stop by themselves should this demo die
    law = ["--controller", args.controller] if args.controller else []
    if args.feedback_timeout_ms is not None:
        law += ["--feedback-timeout-ms", str(args.feedback_timeout_ms)]
    if args.ros2 is not None:
        law += ["--ros2", str(args.ros2)]
    log_dir = Path(args.log_dir) if args.log_dir else Path(tempfile.mkdtemp(prefix="sharedctl-demo-"))
    log_dir.mkdir(parents=True, exist_ok=True)
    common = ["--robot-id", args.robot_id]

    rec = Recorder(loop.feasible)
    udp_errors_before = udp_receive_buffer_errors()
    children: dict[str, Child] = {}
    session = recording = recording_summary = None
    failure = None
    robot_priority = None
    start = time.monotonic()
    try:
        recording = open_demo_recording(args.record, args.robot_id, scenario_arg, scenario.name, can_controller,
                                        seed=None if faults.empty else faults.plan.seed)   # docs/recording.md
        secure.start(log_dir, backstop, wait_listening, args.robot_id,
                     (OPERATOR, ESTOP_OPERATOR) if faults.sends_estop else (OPERATOR,))
        faults.start(controller_ep, args.robot_id, log_dir, backstop, start_child, secure.relay_args())
        children["robot"] = start_child("robot", ["robot", "--scenario", scenario_arg,
                                                  *secure.zenoh_args("robot", ["--zenoh-listen", robot_ep]), *can_robot,
                                                  *faults.robot_arguments(),
                                                  *common, "--duration", backstop, *_json("robot", log_dir)], log_dir)
        robot_priority = raise_priority(children["robot"].popen.pid)
        # the console while the robot starts, before the controller: its start-up (imports, a CPU burst)
        # is over before the controller runs its feedback timeout, and it connects as soon as the
        # controller listens (zenoh_session.CONNECT_RETRY)
        console_argv = ["console", "--script", scenario_arg,
                        *secure.zenoh_args("operator", ["--zenoh-connect", console_ep]), *common]
        console_argv += ["--zenoh-connect", recording.endpoint] if recording is not None and not secure.enabled else []
        console_argv += ["--zenoh-connect", viewer] if viewer is not None else []
        console_argv += [] if secure.enabled else faults.console_listener(free_loopback_port, open_session)
        children["console"] = start_child("console", console_argv + ([] if interactive else ["--headless"]), log_dir,
                                          interactive=interactive)
        if not secure.wait_up("robot", args.robot_id, children["robot"], STARTUP_TIMEOUT,
                              lambda: wait_listening(robot_ep, children["robot"], STARTUP_TIMEOUT)):
            raise RuntimeError(f"robot did not come up on {robot_ep}")
        if viewer is not None:   # the live view: connected to the robot and the controller, the console to it
            children["foxglove"] = start_child("foxglove", [
                "foxglove", "--connect", robot_ep, "--connect", controller_ep, "--zenoh-listen", viewer,
                "--listen", args.foxglove, "--scenario", scenario_arg, *common, "--duration", backstop,
                *_json("foxglove", log_dir)], log_dir)
            if not wait_listening(viewer, children["foxglove"], STARTUP_TIMEOUT):
                raise RuntimeError(f"the Foxglove live view did not come up on {args.foxglove}")
        # the robot is a fresh simulation standing at the scenario's start pose: the first controller is told so;
        # a restarted one (controller.restart_at) resumes from the checkpoint its predecessor left in the log folder
        controller_argv = ["controller", "--scenario", scenario_arg, *law,
                           *secure.zenoh_args("controller", ["--zenoh-listen", controller_ep]),
                           *can_controller, *common, "--duration", backstop,
                           "--checkpoint", str(log_dir / "controller.checkpoint")]
        children["controller"] = start_child("controller", controller_argv + ["--pose", "scenario"]
                                             + _json("controller", log_dir), log_dir)
        if not secure.wait_up("controller", args.robot_id, children["controller"], STARTUP_TIMEOUT,
                              lambda: wait_listening(controller_ep, children["controller"], STARTUP_TIMEOUT)):
            raise RuntimeError(f"controller did not come up on {controller_ep}")
        session = secure.open_session(lambda: open_session(connect=[robot_ep, controller_ep]))
        if recording is not None:
            recording.attach(session)
        faults.attach(secure.operator_session() if secure.enabled and faults.needs_operator_session else session,
                      faults.listener or session, args.robot_id,
                      secure.signer(ESTOP_OPERATOR) if faults.sends_estop else None)
        subscribers = [session.declare_subscriber(keys.truth_key(args.robot_id), rec.on_truth),
                session.declare_subscriber(keys.state_key(args.robot_id), rec.on_state),
                session.declare_subscriber(keys.events_key(args.robot_id), rec.on_event)]
        deadline = time.monotonic() + STARTUP_TIMEOUT
        while subscribers and not rec.in_control.wait(0.1):
            dead = [c.name for c in children.values() if c.popen.poll() is not None]
            if dead or stop.stopped or time.monotonic() > deadline:
                raise RuntimeError(f"{', '.join(dead)} exited early" if dead else "interrupted" if stop.stopped
                                   else "the operator never got control (no RobotState with a lease holder)")
        t0 = rec.operator_start
        faults.arm(t0, rec.lease_wall)
        while not stop.stopped and time.monotonic() < t0 + duration:
            failure = faults.tick(time.monotonic(), children,
                                  lambda: start_child("controller.restart",
                                                      controller_argv + _json("controller.restart", log_dir), log_dir))
            dead = [c.name for n, c in children.items() if c.popen.poll() is not None and not faults.expected_dead(n)]
            if dead or failure:
                failure = failure or f"{', '.join(dead)} exited during the run"
                break
            stop.wait(faults.wait_time(time.monotonic()))
    except RuntimeError as exc:
        failure = str(exc)
    finally:
        settle = None
        faults.continue_all()
        if "console" in children:
            children["console"].stop()
            controller = children.get("controller")
            if controller is not None and controller.popen.poll() is None:
                settle = rec.wait_at_rest(SETTLE_SPEED, SETTLE_TIMEOUT)
        for name in ("controller", "robot", "foxglove"):
            if name in children:
                children[name].stop()
        faults.stop()
        time.sleep(0.1)    # the last ground truth samples
        recording_summary = recording.close() if recording is not None else None
        if session is not None:
            session.close()
        secure.stop()
    result = measure(rec, rec.operator_start, duration)
    udp_errors_after = udp_receive_buffer_errors()
    result["host_udp_receive_buffer_errors"] = (None if udp_errors_before is None or udp_errors_after is None
                                                else udp_errors_after - udp_errors_before)
    summary = {"scenario": scenario.name, "controller": loop.controller.name, "requested_duration": duration, **result,
               "interrupted": stop.stopped, "failure": failure, "settle_seconds": settle,
               "robot_priority": robot_priority,
               "processes": {name: _process_report(children[name], log_dir)
                             for name in ("console", "controller", "robot", "foxglove") if name in children},
               "endpoints": {"robot": robot_ep, "controller": controller_ep, "can": " ".join(can[1:]),
                             **({"foxglove": args.foxglove} if viewer is not None else {})},
               "wall_seconds": time.monotonic() - start, **secure.summary(rec)}
    if recording is not None:
        summary["recording"] = recording_summary
    if not (args.no_reference or failure is not None or stop.stopped):
        # after the run, never beside it: the live processes need the host's CPU (reference_job.py)
        reference = ReferenceJob(scenario_arg, args.controller, duration, log_dir)
        try:
            summary["reference"], summary["reference_plant"] = reference.result(REFERENCE_TIMEOUT + 2.0 * duration,
                                                                                  stop)
        except RuntimeError as exc:
            summary["reference_error"] = str(exc)
        else:
            summary["deviation"] = deviation(result, summary["reference"])
            summary["deviation_plant"] = deviation(result, summary["reference_plant"])
            summary["tolerance"] = TOLERANCE
    clean = (all(c.clean for c in children.values()) and {"console", "controller", "robot"} <= children.keys()
             and secure.clean)
    summary["ok"] = bool(failure is None and clean and result["violations"] == 0 and result["truth_samples"] > 0
                         and result["estops"] == 0)   # an estop means the scenario did not run
    if not faults.empty:   # intended faults: judged as services/faults/stack.py says
        summary.update(faults=faults.plan.specs, injected=faults.report())
        summary["fault_states"] = states_at(rec, _fault_instants(summary["injected"], faults.plan, result))
        summary["ok"] = faults.judge(summary, children, result, failure)
    _report(summary, args, children, log_dir)
    return 0 if summary["ok"] else 1


MAX_ESTOP_STATES = 3     # estops whose surroundings the JSON keeps
REFERENCE_TIMEOUT = 60.0   # s, plus twice the run's duration: the most the demo waits for its references


def _fault_instants(injected: dict, plan, result: dict) -> list[tuple[str, float]]:
    """(label, t on the run's clock) of every fault that fired (its actual instant), of every timed CAN
    bus-off and link blackout (their windows open on the run's clock), and of the first emergency stops
    (the controller's own time of each)."""
    out = [(p["fault"], p["done_at"]) for p in injected.get("processes", []) if p.get("done_at") is not None]
    for stream, link in plan.links.items():
        key = "busoff" if stream == "can" else "blackout"
        out += [(f"{stream}.{key}={start:g},{length:g}", start) for start, length in link.blackouts]
    estops = [e for e in result.get("event_log", []) if e["kind"] == "estop" and e.get("at") is not None]
    out += [("estop", e["at"]) for e in estops[:MAX_ESTOP_STATES]]
    return out


def _check_foxglove(address: str | None, secure: bool) -> str | None:
    """None without ``--foxglove``; else the Zenoh endpoint the live view listens on (the console connects to it:
    peers do not forward its commands). Refused: a non-loopback address, ``--secure``, no 'foxglove' extra."""
    if address is None:
        return None
    listen_address(address, option="--foxglove")
    if secure:
        raise ValueError("--foxglove does not join a --secure demo (its peers reach each other only through the "
                         "router): run `sharedctl foxglove` with the router's credentials instead")
    if importlib.util.find_spec("foxglove") is None:
        raise ValueError("--foxglove needs foxglove-sdk, which comes with the 'foxglove' extra: "
                         "pip install 'sharedctl[foxglove]'")
    return f"tcp/127.0.0.1:{free_loopback_port()}"


def _json(name: str, log_dir: Path) -> list[str]:
    """The options that have child `name` write its exit summary as JSON in the log directory. A summary
    left there by an earlier run is removed first: a child that dies without writing one has none."""
    path = log_dir / f"{name}.json"
    path.unlink(missing_ok=True)
    return ["--json", str(path)]


def _process_report(child: Child, log_dir: Path) -> dict:
    """How the child ended and, if it wrote one (robot, controller), its exit summary (None: none, e.g. killed)."""
    return {**child.report(), "summary": read_json(log_dir / f"{child.name}.json")}


def _report(summary: dict, args, children: dict, log_dir: Path) -> None:
    emit(summary, args.json, _print_table)
    if not summary["ok"]:
        for child in children.values():
            if not child.clean and child.tail():
                print(f"--- {child.name} (exit {child.exit_code}) ---\n{child.tail()}", file=sys.stderr)
        reasons = [r for r in (summary["failure"],
                               f"{summary['violations']} violations" if summary["violations"] else None,
                               f"{summary['estops']} emergency stops" if summary["estops"] else None,
                               "a child did not exit cleanly" if not all(
                                   p["exit_code"] == 0 and not p["killed"]
                                   for p in summary["processes"].values()) else None)
                   if r]
        print(f"sharedctl demo: FAILED ({'; '.join(reasons) or 'see the table'}); logs in {log_dir}", file=sys.stderr)
    elif not args.log_dir:
        shutil.rmtree(log_dir, ignore_errors=True)


def _print_table(summary: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    plant, ref = summary.get("reference_plant", {}), summary.get("reference", {})
    table = Table(title=f"sharedctl demo: {summary['scenario']} ({summary['controller']})")
    table.add_column("measure", no_wrap=True)
    table.add_column("distributed", justify="right")
    table.add_column("sampled, robot plant", justify="right")
    table.add_column("sampled, model plant", justify="right")

    def fmt(v) -> str:
        if isinstance(v, list):
            return "[" + ", ".join(f"{x:.3f}" for x in v) + "]"
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    for key in ("violations", "min_margin", "final_speed", "final_pose", "tracking_rmse", "final_error",
                "human_authority", "switches", "theta_hat", "steps", "duration"):
        table.add_row(key, fmt(summary.get(key)), fmt(plant[key]) if key in plant else "",
                      fmt(ref[key]) if key in ref else "")
    dev_plant, dev = summary.get("deviation_plant", {}), summary.get("deviation", {})
    for key in dev_plant:
        table.add_row(f"Δ {key}", "", fmt(dev_plant[key]), fmt(dev.get(key)))
    for name, proc in summary["processes"].items():
        stop = proc["stop_seconds"]
        table.add_row(f"{name} exit", f"{proc['exit_code']}" + (" (killed)" if proc["killed"] else ""),
                      "" if stop is None else f"stopped in {stop:.2f} s", "")
    table.add_row("estops", str(summary["estops"]), "", "")
    if summary.get("recording"):
        table.add_row("recording", summary["recording"]["mcap"], f"{summary['recording']['messages']} messages", "")
    table.add_row("result", "[green]OK[/green]" if summary["ok"] else "[red]FAILED[/red]", "", "")
    Console().print(table)
