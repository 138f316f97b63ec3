"""The running stack, measured from outside: robot + controller processes on a host-local CAN bus.

One run: `sharedctl robot` and `sharedctl controller --rate R` (paper_convex, udp_multicast on a
private port, Zenoh on private loopback ports) as child processes; this process listens on the
same bus (udp_multicast delivers every frame to every listener, kernel-stamped on arrival) and
plays the operator over Zenoh. In the same run, two probe processes (hop_probe.py) send bare
timestamps over Zenoh and over a second udp_multicast port: the transport floors. With `turns`,
the controller is started that many times one after the other (each connects to this process's
Zenoh endpoint), and with `floor` the bare loop of machine_floor.py runs on the same bus after each;
every figure is taken window by window (`analyse_turns`), and this process's garbage collector is
off for the run (its operator must not pause).

* loop: torque bursts (three Set_Input_Torque frames per tick) on the bus → rate, period jitter
  |Δt − T| and periods without a burst; beside them the daemon's own exit summary (missed/late ticks,
  wake-up lateness, compute time…), the JSON it writes with `--json` (`daemon_summary`).
* sensor → torque: for each burst, the age of the wheel estimates the tick used: the oldest of
  the three axes' newest Get_Encoder_Estimates that arrived before the tick started — the burst
  minus the daemon's median "torque out" time (tick start → torque frames sent; its exit summary),
  since a frame arriving during the computation was not used. The daemon reports its own figure
  beside it (`daemon.sensor_to_torque_*`: from the kernel arrival stamp of the oldest estimate a
  tick used to its torque frames handed to the bus), exact about which estimates a tick used; the
  bus figure is independent of the daemon but attributes a tick whose computation was much shorter
  than the median to the previous period's estimates. (The daemon's whole compute time,
  used before it reported the send time, also counts the telemetry after the send: it cut off
  frames the tick had used and charged it the previous period's.)
* operator → torque: the operator's y deflection alternates sign every command; the latency of a
  command is from its send time to the first torque burst whose sign follows it. With `compare_qos`,
  the operator sends its commands in pairs (one of each sign) alternately on two publishers of the
  same key: one with Zenoh's default QoS, one with the operator stream's own (services/zenoh_qos.py:
  REAL_TIME, BLOCK, express); `latency.operator_to_torque_by_qos_us` holds each one's figures, from
  the same controllers in the same minutes.
* the drives' send jitter: |Δt − T| between the simulated drives' bursts of encoder estimates (500 Hz),
  the other side of sensor → torque.
* bus load: every frame seen on the bus in the window, worst-case stuffed (bus_load.py).
* CPU: utime + stime of both processes from /proc/<pid>/stat over the window; beside it the guest's
  steal time over the window (/proc/stat), as the machine floor reports its own.
"""
from __future__ import annotations

import gc
import os
import struct
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sharedctl.protocol import keys
from sharedctl.protocol.messages import ControlRequest, OperatorCommand
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.protocol.odrive_enums import CommandId

from sharedctl.services import can_bus, children, zenoh_qos, zenoh_session
from sharedctl.services.summary_output import read_json
from .bus_load import bus_load
from .hop_probe import PROBE_CAN_ID, PROBE_KEY, unpack_time
from . import machine_floor
from .machine_floor import steal_seconds
from .statistics import group_bursts, missed_periods, percentiles, period_jitter

ROBOT_ID = "robot1"
SCENARIO = "paper_convex"
OPERATOR_RATE = 100.0      # Hz, commands (each flips the deflection's sign)
DEFLECTION = 0.2           # normalised y deflection: u_h = ±k_p·0.2 = ±4 N, the robot stays put
PROBE_RATE = 500.0         # Hz, each transport probe
DRIVES_RATE = 500.0        # Hz, the simulated drives' encoder estimates (paper_convex's [robot_sim] default)
SENSOR_LEAD_US = 250.0     # the controller's sensor lead (its default), passed explicitly: the floor's figures use it
SETTLE = 2.5               # s after start before the window opens (arming, Zenoh links)
# s the floor's process may take beyond its run (start, calibration) before the bench gives up
FLOOR_START_LIMIT = 30.0
FLOOR_WORK_US = 400.0      # µs of CPU per period in the floor's loop where a controller's own figures are missing

@dataclass
class Frame:
    t: float            # kernel receive time (wall clock, s)
    can_id: int
    dlc: int
    remote: bool
    extended: bool
    data: bytes


@dataclass
class Listener:
    """A thread draining one bus into a list (stops with `stop`)."""

    bus: object
    frames: list = field(default_factory=list)
    app_times: list = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)

    def start(self) -> threading.Thread:
        thread = threading.Thread(target=self._run, daemon=True)
        thread.start()
        return thread

    def _run(self) -> None:
        while not self.stop.is_set():
            try:
                msg = self.bus.recv(timeout=0.1)
            except Exception:  # noqa: BLE001 — a bad datagram is skipped, the listener goes on
                continue
            if msg is None:
                continue
            now = time.time()
            self.frames.append(Frame(msg.timestamp or now, msg.arbitration_id, msg.dlc, msg.is_remote_frame,
                                     msg.is_extended_id, bytes(msg.data)))
            self.app_times.append(now)


def _cpu_seconds(pid: int) -> float | None:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def _command(counter: int, session_id: str, sign: float) -> OperatorCommand:
    q0 = (-0.9, 3.0, 0.0)
    return OperatorCommand(
        operator_id="bench", session_id=session_id, seq=counter, send_time=time.time(),
        joystick=(0.0, sign * DEFLECTION, 0.0), q_d=q0, qd_d=(0.0, 0.0, 0.0), qdd_d=(0.0, 0.0, 0.0),
        deadman=True, estop=False, control_request=ControlRequest.NONE,
    )


def cpu_plan() -> dict:
    """Which CPU each process gets: on a machine with two or more, the robot on the first and the controller's
    loop on the last (its other threads kept off it); on one CPU, no pinning."""
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return {}
    return {"robot": cpus[0], "controller_loop": cpus[-1]}


@dataclass
class Operator:
    """The bench's operator: a command every 1/OPERATOR_RATE s, its y deflection flipping sign each time. With a
    `default_publisher` (Zenoh's default QoS on the same key) the commands go in pairs, one of each sign, on it and
    on `publisher` by turns; `log` holds (send time, sign, "default" | "streams")."""

    publisher: object
    default_publisher: object | None = None
    session_id: str = field(default_factory=lambda: os.urandom(8).hex())
    log: list = field(default_factory=list)
    seq: int = 0
    sign: float = 1.0
    next_at: float = field(default_factory=time.monotonic)

    def run(self, until, on_each=None) -> None:
        """Send commands until `until()` is true (checked before each); `on_each()` after each."""
        while not until():
            self.seq += 1
            self.sign = -self.sign
            cmd = _command(self.seq, self.session_id, self.sign)
            default = self.default_publisher is not None and (self.seq - 1) // 2 % 2 == 0
            (self.default_publisher if default else self.publisher).put(encode_message(cmd))
            self.log.append((cmd.send_time, self.sign, "default" if default else "streams"))
            if on_each is not None:
                on_each()
            self.next_at = max(self.next_at + 1.0 / OPERATOR_RATE, time.monotonic() - 1.0 / OPERATOR_RATE)
            time.sleep(max(self.next_at - time.monotonic(), 0.0))


def run(rate_hz: float, seconds: float, log_dir: Path | None = None, probes: bool = True,
        controller_args: tuple[str, ...] = (), pin: bool = True, turns: int = 1, floor: bool = False,
        compare_qos: bool = False) -> dict:
    """`_run` with this process's cyclic garbage collector off (as `timeit` does): the listener's list of
    frames grows to hundreds of thousands of objects, over which a full collection held the GIL for
    40–95 ms — the bench's operator sent nothing meanwhile and then a burst. Frames hold no cycles;
    reference counting frees them."""
    enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        return _run(rate_hz, seconds, log_dir, probes, controller_args, pin, turns, floor, compare_qos)
    finally:
        if enabled:
            gc.enable()


def _run(rate_hz: float, seconds: float, log_dir: Path | None, probes: bool, controller_args: tuple[str, ...],
         pin: bool, turns: int, floor: bool, compare_qos: bool = False) -> dict:
    """Start the stack at `rate_hz` for `seconds` of measurement; returns the figures (see module doc).

    `turns` > 1: the controller runs that many times, `seconds / turns` of measurement each, one after the
    other beside the same robot, listener and probes (each a whole daemon: start, arming, exit). `floor`:
    after each controller, the bare loop (machine_floor.py) on the same bus and CPU for as long as that
    controller ran, with the amounts of work it reported; its figures are in `machine_floor`."""
    log_dir = Path(log_dir or tempfile.mkdtemp(prefix="sharedctl-bench-"))
    can_port, probe_port = children.free_udp_port(), children.free_udp_port()
    z_robot, z_bench = (f"tcp/127.0.0.1:{zenoh_session.free_loopback_port()}" for _ in range(2))
    can_args = ["--can-interface", "udp_multicast", "--can-option", f"port={can_port}"]
    per_turn = seconds / turns
    daemon_seconds = SETTLE + per_turn + 0.5
    whole = turns * (daemon_seconds + 10.0) * (2 if floor else 1) + 10.0   # a bound: everything is stopped at the end
    cpus = cpu_plan() if pin else {}
    robot_cpu = ["--cpu", str(cpus["robot"])] if cpus else []
    controller_cpu = ["--cpu", str(cpus["controller_loop"])] if cpus else []
    started, daemon_turns, floor_runs = [], [], []
    bus = probe_bus = session = None
    listener = probe_listener = None
    zenoh_arrivals: list[tuple[float, float]] = []
    try:
        bus = can_bus.open_bus(can_bus.resolve("udp_multicast", None, {"port": can_port}))
        probe_bus = can_bus.open_bus(can_bus.resolve("udp_multicast", None, {"port": probe_port}))
        listener, probe_listener = Listener(bus), Listener(probe_bus)
        listener.start()
        probe_listener.start()
        robot = children.start_child("robot", ["robot", "--scenario", SCENARIO, *can_args, "--zenoh-listen", z_robot,
                                               "--robot-id", ROBOT_ID, "--duration", f"{whole:.1f}", *robot_cpu],
                                     log_dir)
        started.append(robot)
        robot_priority = children.raise_priority(robot.popen.pid)
        if not children.wait_listening(z_robot, robot, 20.0):
            raise RuntimeError(f"robot did not start (log: {robot.log})")
        robot_priority = _realtime(robot.popen.pid) or robot_priority
        session = zenoh_session.open_session([z_bench], [])        # each controller connects to it
        key = keys.operator_cmd_key(ROBOT_ID)
        operator = Operator(zenoh_qos.declare_publisher(session, key),
                            zenoh_qos.declare_publisher(session, key, zenoh_qos.DEFAULT) if compare_qos else None)
        subscriber = session.declare_subscriber(
            PROBE_KEY, lambda sample: zenoh_arrivals.append((time.time(), unpack_time(sample.payload.to_bytes()))))
        if probes:
            started.append(_start_probe("zenoh_probe", ["zenoh", z_bench, f"{whole:.1f}", f"{PROBE_RATE:g}"], log_dir))
            started.append(_start_probe("can_probe", ["can", str(probe_port), f"{whole:.1f}", f"{PROBE_RATE:g}"],
                                        log_dir))
        for turn in range(turns):
            name = "controller" if turns == 1 else f"controller_{turn + 1}"
            z_ctrl = f"tcp/127.0.0.1:{zenoh_session.free_loopback_port()}"
            summary_path = log_dir / f"{name}.json"
            controller = children.start_child(name, [
                "controller", "--scenario", SCENARIO, *can_args, "--zenoh-listen", z_ctrl, "--zenoh-connect", z_bench,
                "--robot-id", ROBOT_ID, "--rate", f"{rate_hz:g}", "--duration", f"{daemon_seconds:.1f}", "--quiet",
                "--sensor-lead-us", f"{SENSOR_LEAD_US:g}", "--json", str(summary_path), *controller_cpu,
                "--pose", "scenario", "--checkpoint", str(log_dir / f"{name}.checkpoint"),
                *controller_args], log_dir)
            started.append(controller)
            daemon_turns.append(_daemon_turn(controller, z_ctrl, robot, operator, per_turn, summary_path))
            if floor:
                floor_runs.append(_floor_turn(daemon_turns[-1]["summary"], operator, rate_hz, daemon_seconds,
                                              cpus.get("controller_loop"), can_port))
        subscriber.undeclare()
        for publisher in (operator.publisher, operator.default_publisher):
            if publisher is not None:
                publisher.undeclare()
    finally:
        for child in started:
            child.stop()
        for lst in (listener, probe_listener):
            if lst is not None:
                lst.stop.set()
        time.sleep(0.15)
        if session is not None:
            session.close()
        for b in (bus, probe_bus):
            if b is not None:
                b.shutdown()
    windows = [t["window"] for t in daemon_turns]
    figures = analyse_turns(listener.frames, operator.log, windows, rate_hz, [t["summary"] for t in daemon_turns])
    figures["cpu"] = _cpu_turns([t["cpu"] for t in daemon_turns])

    def inside(t):
        return any(lo <= t <= hi for lo, hi in windows)

    figures["latency"]["zenoh_floor_us"] = percentiles(
        [arrived - sent for arrived, sent in zenoh_arrivals if inside(sent)], 1e6)
    probe = [f for f in probe_listener.frames if f.can_id == PROBE_CAN_ID and f.dlc == 8]
    figures["latency"]["can_floor_us"] = percentiles([f.t - unpack_time(f.data) for f in probe if inside(f.t)], 1e6)
    if floor_runs:
        figures["machine_floor"] = dict(
            machine_floor.figures(floor_runs),
            bus=analyse_turns(listener.frames, [], [r["window"] for r in floor_runs], rate_hz,
                              [{}] * len(floor_runs))["loop"],
            turns=[_turn_pair(listener.frames, rate_hz, t, r) for t, r in zip(daemon_turns, floor_runs)])
    figures["windows"] = windows
    figures["processes"] = {c.name: c.report() for c in started}
    figures["robot_priority"] = robot_priority
    figures["cpus"] = cpus
    figures["log_dir"] = str(log_dir)
    return figures


def _daemon_turn(controller: children.Child, z_ctrl: str, robot: children.Child, operator: Operator,
                 seconds: float, summary_path: Path) -> dict:
    """One controller from its start to its exit (its summary then at `summary_path`), the operator sending
    throughout; the window opens SETTLE s after it listens."""
    if not children.wait_listening(z_ctrl, controller, 20.0):
        raise RuntimeError(f"{controller.name} did not start (log: {controller.log})")
    opens = time.time() + SETTLE
    window = (opens, opens + seconds)
    marks = []

    def mark() -> None:
        if len(marks) == 0 and time.time() >= window[0] or len(marks) == 1 and time.time() >= window[1]:
            marks.append((time.monotonic(), {c.name: _cpu_seconds(c.popen.pid) for c in (robot, controller)},
                          steal_seconds()))

    operator.run(lambda: len(marks) == 2, mark)
    operator.run(lambda: controller.popen.poll() is not None or time.time() > window[1] + 10.0)
    return {"window": window, "summary": daemon_summary(summary_path), "cpu": (marks[0], marks[1])}


def _floor_turn(summary: dict, operator: Operator, rate_hz: float, seconds: float, cpu: int | None,
                can_port: int) -> dict:
    """The bare loop on the bus for `seconds`, with the amounts of work of the controller before it (its
    median tick start → torques computed, its output instant, and its median thread CPU per period), the
    operator sending throughout."""
    pre = summary.get("torque_ready_p50_us") or summary.get("torque_out_p50_us") or FLOOR_WORK_US
    work = max(summary.get("loop_cpu_p50_us") or FLOOR_WORK_US, pre)
    hold = summary.get("torque_at_us") or 0.0
    with machine_floor.run(rate_hz, seconds, work_us=work, pre_send_us=pre, cpu=cpu, can_port=can_port,
                           hold_us=hold) as loop:
        give_up = time.monotonic() + seconds + FLOOR_START_LIMIT
        operator.run(lambda: loop.done() or time.monotonic() > give_up)
        return loop.result(max(give_up - time.monotonic(), 0.0) + 1.0)


def _turn_pair(frames: list[Frame], rate_hz: float, daemon: dict, floor: dict) -> dict:
    """One controller and the bare loop after it, side by side."""
    summary = daemon["summary"]
    floor_loop = analyse_turns(frames, [], [floor["window"]], rate_hz, [{}])["loop"]
    daemon_loop = analyse_turns(frames, [], [daemon["window"]], rate_hz, [summary])["loop"]
    cpu = _cpu_turns([daemon["cpu"]])
    return {
        "daemon": {"deadline_misses": daemon_loop["deadline_misses"], "jitter_p99_us": daemon_loop["jitter_p99_us"],
                   "misses_woke_late": summary.get("misses_woke_late"), "misses_not_run": summary.get("misses_not_run"),
                   "misses_working": summary.get("misses_working"), "steal_s": cpu.get("steal_s"),
                   "loop_cpu_p50_us": summary.get("loop_cpu_p50_us"), "miss_times": summary.get("miss_times")},
        "floor": {"deadline_misses": floor["missed"] + floor["late"], "jitter_p99_us": floor_loop["jitter_p99_us"],
                  "steal_s": floor["steal_s"],
                  "loop_cpu_p50_us": float(np.median(floor["samples"]["cpu"])) / 1e3 if floor["ticks"] else None},
    }


def _realtime(pid: int) -> str | None:
    """SCHED_FIFO 10 for the robot's loop thread (its main thread, once its other threads exist): the
    simulated drives stand for microcontrollers that a loaded host must not starve. None if not permitted."""
    try:
        os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(10))
        return "SCHED_FIFO 10 (loop thread)"
    except (OSError, AttributeError):
        return None


def _start_probe(name: str, argv: list[str], log_dir: Path) -> children.Child:
    import subprocess

    log = log_dir / f"{name}.log"
    with open(log, "wb") as out:
        popen = subprocess.Popen([*children.python_module("sharedctl.services.studies.bench.hop_probe"), *argv],
                                 stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    return children.Child(name, popen, log)


# the figures of the controller's exit summary (loop_stats.py) the bench reports, in the bench's names: the
# controller's `jitter_*` (its ticks' lateness after their deadlines) is the bench's `lateness_*`
DAEMON_KEYS = ("estops", "ticks", "rate_hz", "missed", "late", "lateness_p50_us", "lateness_p99_us", "lateness_max_us",
               "compute_p50_us", "compute_p99_us", "cpu_percent", "torque_out_p50_us", "torque_out_p99_us",
               "sensor_to_torque_p50_us", "sensor_to_torque_p99_us", "loop_cpu_p50_us", "loop_cpu_p99_us",
               "sensor_waits", "sensor_waits_in_vain", "misses_woke_late", "misses_not_run", "misses_working",
               "misses_working_cpu_p50_us", "misses_working_frames_p50", "misses_working_commands_p50", "frames_rx",
               "torque_ready_p50_us", "torque_ready_p99_us", "torque_at_us")
CONTROLLER_NAMES = {"lateness_p50_us": "jitter_p50_us", "lateness_p99_us": "jitter_p99_us",
                    "lateness_max_us": "jitter_max_us"}


def daemon_summary(path: Path) -> dict:
    """The controller's exit summary (its `--json` file) as the bench reports it: `DAEMON_KEYS`, the CPU share in
    whole percent, the first misses as [s, cause] pairs. {} if the controller wrote none."""
    summary = read_json(path)
    if summary is None:
        return {}
    out = {key: summary.get(CONTROLLER_NAMES.get(key, key)) for key in DAEMON_KEYS}
    if out["cpu_percent"] is not None:
        out["cpu_percent"] = round(out["cpu_percent"])
    out["miss_times"] = [[m["t_s"], m["cause"]] for m in summary.get("miss_times", [])]
    return out


def _cpu_turns(turns) -> dict:
    """Robot + controller CPU over the windows of one or more turns ((start, end) marks each), as a fraction of
    the windows' wall time; the guest's steal summed over them."""
    wall, used, steal = 0.0, {}, 0.0
    for start, end in turns:
        if start is None or end is None:
            return {"fraction_of_one_core": None}
        wall += end[0] - start[0]
        for name, after in end[1].items():
            key = "controller" if name.startswith("controller") else name
            before = start[1].get(name)
            if after is not None and before is not None:
                used[key] = used.get(key, 0.0) + after - before
        steal = None if steal is None or start[2] is None or end[2] is None else steal + end[2] - start[2]
    per = {name: seconds / wall for name, seconds in used.items()} if wall > 0 else {}
    return {"fraction_of_one_core": sum(per.values()) if per else None, "per_process": per, "window_s": wall,
            "steal_s": steal}


def merge_summaries(summaries: list[dict]) -> dict:
    """The controllers' exit summaries as one: counts summed; of each percentile, the worst turn's (p99, max)
    or the median of the turns' (p50) — labelled so in docs/performance.md. One summary stays as it is."""
    if len(summaries) == 1 or not all(summaries):     # one missing line: no sum at all (the bus counts instead)
        return summaries[0] if len(summaries) == 1 else {}
    out = {}
    known = all(s.get("misses_working") is not None for s in summaries)
    working = [s for s in summaries if s.get("misses_working")] if known else summaries
    for key in summaries[0]:
        # what the overrunning periods used and handled: only the controllers that had such periods say
        values = [s.get(key) for s in (working if key.startswith("misses_working_") else summaries)]
        if not values:
            out[key] = 0.0
            continue
        if any(v is None for v in values):
            out[key] = None
        elif isinstance(values[0], list):
            out[key] = [item for value in values for item in value]
        elif key == "rate_hz":
            out[key] = float(np.average(values, weights=[s["ticks"] for s in summaries]))
        elif isinstance(values[0], int):
            out[key] = int(sum(values))
        elif "_p99" in key or "_max" in key:
            out[key] = max(values)
        else:
            out[key] = float(np.median(values))
    out["turns"] = len(summaries)
    return out


def analyse(frames: list[Frame], operator_log, window, rate_hz: float, summary: dict) -> dict:
    """The loop, latency and bus-load figures from the frames seen on the bus in `window`."""
    return analyse_turns(frames, operator_log, [window], rate_hz, [summary])


def analyse_turns(frames: list[Frame], operator_log, windows, rate_hz: float, summaries: list[dict]) -> dict:
    """`analyse` over several windows (one controller each, `summaries` theirs): every interval, age and latency
    is taken within one window, never across the gap between two; the samples are then pooled."""
    period = 1.0 / rate_hz
    parts = [_window(frames, operator_log, w, period, s) for w, s in zip(windows, summaries)]

    def pool(name):
        return np.concatenate([np.asarray(p[name], dtype=float) for p in parts])

    summary = merge_summaries(summaries)
    missed_bus = sum(p["missed_bus"] for p in parts)
    span = sum(p["span"] for p in parts)
    jitter = pool("jitter")
    loop = {
        "rate_hz": sum(len(p["bursts"]) - 1 for p in parts if len(p["bursts"]) > 1) / span if span > 0 else 0.0,
        "deadline_misses": (summary["missed"] + summary["late"]) if summary else missed_bus,
        "jitter_p99_us": percentiles(jitter, 1e6)["p99"],
        "jitter_p50_us": percentiles(jitter, 1e6)["p50"],
        "periods_without_torque_on_bus": missed_bus,
        "drives_send_jitter_us": percentiles(pool("drives_jitter"), 1e6),
        "bursts": sum(len(p["bursts"]) for p in parts),
        "daemon": summary,
        "sensor_age_excludes_compute_us": float(np.median([p["compute"] for p in parts])) * 1e6 if parts else 0.0,
    }
    if len(parts) > 1:
        loop["daemon_turns"] = [s for s in summaries]
    seconds = sum(hi - lo for lo, hi in windows)
    inside = [f for p in parts for f in p["inside"]]
    load = bus_load([(f.dlc, f.remote, f.extended) for f in inside if f.can_id != PROBE_CAN_ID], seconds)
    counts = {k: sum(p["counts"][k] for p in parts) for k in ("torque", "encoder", "all")}
    operator = [pair for p in parts for pair in p["operator"]]
    latency = {"sensor_to_torque_us": percentiles(pool("sensor"), 1e6),
               "operator_to_torque_us": percentiles([lat for _, lat in operator], 1e6)}
    labels = sorted({label for label, _ in operator if label is not None})
    if labels:
        latency["operator_to_torque_by_qos_us"] = {
            label: percentiles([lat for lab, lat in operator if lab == label], 1e6) for label in labels}
    return {
        "loop": loop,
        "latency": latency,
        "bus_load": {"fraction_1mbit": load, "frames_per_s": {k: v / seconds for k, v in counts.items()}},
    }


def _window(frames: list[Frame], operator_log, window, period: float, summary: dict) -> dict:
    """The samples of one window: torque bursts, their period jitter and missing periods, the drives' send
    jitter, sensor ages, operator latencies, and the frames inside it."""
    lo, hi = window
    inside = [f for f in frames if lo <= f.t <= hi]
    torque = [f for f in inside if not f.remote and (f.can_id & 0x1F) == CommandId.SET_INPUT_TORQUE]
    encoder = [f for f in inside if not f.remote and (f.can_id & 0x1F) == CommandId.GET_ENCODER_ESTIMATES]
    bursts = group_bursts([f.t for f in torque], 0.25 * period)
    burst_set = set(bursts)
    first_frames = [f for f in torque if f.t in burst_set]
    # frames that arrived after the tick started were not used by it: the tick started the daemon's median
    # "torque out" time (tick start → frames handed to the bus) before the burst; an older daemon reports
    # only its whole compute time (which includes the telemetry after the send)
    before_send = (summary.get("torque_out_p50_us") or summary.get("compute_p50_us", 0.0)) if summary else 0.0
    compute = before_send * 1e-6
    operator = [entry for entry in operator_log if lo <= entry[0] <= hi]
    return {
        "bursts": bursts, "span": bursts[-1] - bursts[0] if len(bursts) > 1 else 0.0,
        "jitter": period_jitter(bursts, period), "missed_bus": missed_periods(bursts, period),
        "drives_jitter": period_jitter(group_bursts([f.t for f in encoder], 0.25 / DRIVES_RATE), 1.0 / DRIVES_RATE),
        "compute": compute, "sensor": _sensor_ages(bursts, encoder, compute),
        "operator": _operator_latencies(first_frames, torque, operator, period),
        "inside": inside, "counts": {"torque": len(torque), "encoder": len(encoder), "all": len(inside)},
    }


def _sensor_ages(bursts: list[float], encoder: list[Frame], compute: float) -> list[float]:
    """For each burst: burst time − the oldest of the axes' newest estimates that arrived before the tick used them."""
    by_node: dict[int, list[float]] = {}
    for f in encoder:
        by_node.setdefault(f.can_id >> 5, []).append(f.t)
    series = [np.asarray(v) for v in by_node.values()]
    ages = []
    for tb in bursts:
        cutoff = tb - compute
        newest = []
        for times in series:
            k = int(np.searchsorted(times, cutoff)) - 1
            if k < 0:
                break
            newest.append(times[k])
        if len(newest) == len(series) and series:
            ages.append(tb - min(newest))
    return ages


def _operator_latencies(first_frames: list[Frame], torque: list[Frame], operator_log,
                        period: float) -> list[tuple[str | None, float]]:
    """Send time of each command → the first torque burst after it whose wheel-0 torque has the command's sign
    (the sign convention learnt from the run: the majority of sign(τ₀)·sign(command) over the bursts), with the
    command's QoS label (its log entry's third field; None without one)."""
    wheel0 = ([(f.t, struct.unpack("<f", f.data[:4])[0]) for f in torque if (f.can_id >> 5) == (torque[0].can_id >> 5)]
              if torque else [])
    if not wheel0 or not operator_log:
        return []
    times = np.array([t for t, _ in wheel0])
    signs = np.sign([tau for _, tau in wheel0])
    sent = np.array([entry[0] for entry in operator_log])
    wanted = np.array([entry[1] for entry in operator_log])
    labels = [entry[2] if len(entry) > 2 else None for entry in operator_log]
    # which command was current at each burst (the last one sent before it), for the sign convention
    current = np.searchsorted(sent, times) - 1
    valid = (current >= 0) & (signs != 0)
    if not np.any(valid):
        return []
    convention = 1.0 if np.sum(signs[valid] * wanted[current[valid]]) >= 0 else -1.0
    out = []
    for k in range(len(sent) - 1):
        lo, hi = np.searchsorted(times, sent[k]), np.searchsorted(times, sent[k + 1])
        for j in range(lo, hi):
            if signs[j] * convention == wanted[k]:
                out.append((labels[k], times[j] - sent[k]))
                break
    return out
