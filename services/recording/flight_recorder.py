"""The flight recorder of one process: an MCAP file of the robot's Zenoh traffic and a candump log of its CAN bus.

``--record DIR`` (demo, controller, record) creates in DIR::

    <role>-<UTC time>.mcap       every message under sharedctl/v1/<robot>/** (mcap_writer), and the
                                 derived views foxglove.Log and foxglove.SceneUpdate (views)
    <role>-<UTC time>.can.log    every CAN frame on the bus, candump -L format (can_log)

The MCAP file starts with two metadata records: ``sharedctl`` (version, wire version, role,
robot id, seed, command line, start time, CAN bus) and ``scenario`` (its name, where it came
from, and the TOML text itself, so a recording can be plotted without the scenario file).

A process records what reaches its own Zenoh session. Peers do not forward for each other, so
the session has to be connected to every publisher of interest: :meth:`FlightRecorder.attach`
subscribes on a session the process already has, :meth:`FlightRecorder.listen` opens one that
publishers can connect to.
"""
from __future__ import annotations

import sys
import time
from importlib import resources
from pathlib import Path

import sharedctl
from sharedctl.protocol import keys
from sharedctl.protocol.messages import WIRE_VERSION

from .. import can_bus, zenoh_session
from .can_log import CanLogger
from .mcap_writer import McapRecorder
from .views import DerivedViews, views_for

METADATA_RUN = "sharedctl"
METADATA_SCENARIO = "scenario"


def add_argument(parser) -> None:
    parser.add_argument("--record", metavar="DIR",
                        help="record every Zenoh message of the robot (MCAP) and the CAN bus (candump log) "
                             "into DIR (docs/recording.md)")


def scenario_source(path_or_name: str | None) -> tuple[str, str]:
    """(where it came from, TOML text) of a scenario file or packaged name; ("", "") if unknown."""
    if not path_or_name:
        return "", ""
    path = Path(path_or_name)
    try:
        if path.exists():
            return str(path.resolve()), path.read_text(encoding="utf-8")
        packaged = resources.files("sharedctl").joinpath(f"scenarios/{path_or_name}.toml")
        if packaged.is_file():
            return f"packaged:{path_or_name}", packaged.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError, ValueError):
        pass
    return str(path_or_name), ""


def run_metadata(role: str, robot_id: str, scenario: str | None, scenario_name: str | None, seed,
                 can_spec: can_bus.BusSpec | None, extra: dict | None = None) -> dict[str, dict[str, str]]:
    """The two metadata records: the run and its scenario."""
    source, toml_text = scenario_source(scenario)
    run = {
        "version": sharedctl.__version__,
        "wire_version": f"{WIRE_VERSION[0]}.{WIRE_VERSION[1]}",
        "role": role,
        "robot_id": robot_id,
        "seed": "none" if seed is None else str(seed),
        "command_line": " ".join(["sharedctl", *sys.argv[1:]]) if sys.argv else "",
        "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "log_time": "Unix time of arrival at the recorder, ns",
        "publish_time": "Zenoh timestamp if any, else the message's send_time/time (sender clock), ns",
        "can_bus": can_spec.describe() if can_spec is not None else "none",
        **{k: str(v) for k, v in (extra or {}).items()},
    }
    return {METADATA_RUN: run,
            METADATA_SCENARIO: {"name": scenario_name or "", "source": source, "toml": toml_text}}


def recording_views(robot_id: str, scenario: str | None) -> DerivedViews:
    """The live view's derived channels (foxglove.Log, foxglove.SceneUpdate) for the recording; the scene
    draws the scenario's set when the scenario loads (one that does not is only metadata)."""
    try:
        return views_for(robot_id, scenario)
    except ValueError:
        return views_for(robot_id, None)


class FlightRecorder:
    """MCAP + CAN log of one process; ``close()`` finishes both files and returns a summary."""

    def __init__(self, directory: Path | str, role: str, robot_id: str, *, scenario: str | None = None,
                 scenario_name: str | None = None, seed=None, can_spec: can_bus.BusSpec | None = None,
                 extra: dict | None = None) -> None:
        self.robot_id = keys.check_robot_id(robot_id)
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        base = self.directory / f"{role}-{stamp}"
        n = 1
        while base.with_suffix(".mcap").exists():
            n += 1
            base = self.directory / f"{role}-{stamp}-{n}"
        self.mcap_path = base.with_suffix(".mcap")
        self.can_log_path = base.with_suffix(".can.log") if can_spec is not None else None
        metadata = run_metadata(role, robot_id, scenario, scenario_name, seed, can_spec, extra)
        self.mcap = McapRecorder(self.mcap_path, metadata, library=f"sharedctl {sharedctl.__version__}",
                                 derive=recording_views(robot_id, scenario))
        self.can_log = None
        if can_spec is not None:
            try:
                self.can_log = CanLogger(self.can_log_path, can_spec)
            except Exception:
                self.mcap.close()
                raise
        self._subscribers: list = []
        self._own_sessions: list = []
        self.endpoint: str | None = None      # where publishers connect, once listen() was called
        self.started = time.monotonic()

    def attach(self, session) -> None:
        """Record everything about the robot that reaches ``session`` (its own publications included)."""
        self._subscribers.append(session.declare_subscriber(keys.robot_pattern(self.robot_id), self.mcap.on_sample))

    def listen(self, endpoint: str, connect: list[str] | None = None):
        """Open a session of the recorder's own on a loopback endpoint (publishers connect to it)."""
        session = zenoh_session.open_session(listen=[endpoint], connect=connect)
        self._own_sessions.append(session)
        self.endpoint = endpoint
        self.attach(session)
        return session

    def close(self) -> dict:
        """Stop receiving, finish the files; a summary for the run's report."""
        for subscriber in self._subscribers:
            try:
                subscriber.undeclare()
            except Exception:  # noqa: BLE001 — the session may already be closed by its owner
                pass
        self._subscribers.clear()
        for session in self._own_sessions:
            session.close()
        self._own_sessions.clear()
        frames = self.can_log.close() if self.can_log is not None else None
        counts = self.mcap.close()
        return {
            "mcap": str(self.mcap_path),
            "can_log": str(self.can_log_path) if self.can_log_path else None,
            "messages": counts.messages,
            "topics": dict(sorted(counts.per_topic.items())),
            "undecoded": counts.undecoded,
            "dropped": counts.dropped,
            "write_error": counts.write_error,
            "view_errors": counts.derive_errors,
            "can_frames": frames,
            "can_errors": self.can_log.errors if self.can_log is not None else None,
            "seconds": round(time.monotonic() - self.started, 3),
        }
