"""``--record DIR`` for the launchers (``sharedctl demo``, ``sharedctl controller``): a few calls each.

The demo records in its own process: a recorder session listens on a loopback endpoint that
the operator console also connects to (the console's commands and heartbeats reach no peer it
is not connected to), and the demo's observer session, connected to the robot and the
controller, is attached too; the CAN log listens on the controller's bus. The controller
records what reaches its own session (operator commands, its telemetry, events, heartbeats)
and the CAN bus it drives.
"""
from __future__ import annotations

import argparse

from .. import can_bus
from ..zenoh_session import free_loopback_port
from .flight_recorder import FlightRecorder, add_argument

__all__ = ["add_argument", "bus_spec_from_argv", "open_demo_recording", "open_process_recording", "summary_line"]


def bus_spec_from_argv(argv: list[str]) -> can_bus.BusSpec:
    """The bus a child is given by ``--can-interface/--can-channel/--can-option`` arguments."""
    parser = argparse.ArgumentParser(add_help=False)
    can_bus.add_arguments(parser)
    args, _ = parser.parse_known_args(argv)
    return can_bus.spec_from_args(args)


def open_demo_recording(directory: str | None, robot_id: str, scenario: str, scenario_name: str,
                        controller_can_argv: list[str], seed=None, extra: dict | None = None) -> FlightRecorder | None:
    """None without ``--record``; else a recorder listening on ``recorder.endpoint`` (give it to the console)."""
    if not directory:
        return None
    try:
        recorder = FlightRecorder(directory, "demo", robot_id, scenario=scenario, scenario_name=scenario_name,
                                  seed=seed, can_spec=bus_spec_from_argv(controller_can_argv), extra=extra)
    except (OSError, ValueError) as exc:
        raise RuntimeError(f"cannot record into {directory}: {exc}") from exc
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    try:
        recorder.listen(endpoint)
    except Exception as exc:
        recorder.close()
        raise RuntimeError(f"recorder session on {endpoint}: {exc}") from exc
    return recorder


def open_process_recording(directory: str | None, role: str, robot_id: str, scenario: str, scenario_name: str,
                           session, spec: can_bus.BusSpec | None, seed=None) -> FlightRecorder | None:
    """None without ``--record``; else a recorder attached to the process's own session and a log of its bus."""
    if not directory:
        return None
    recorder = FlightRecorder(directory, role, robot_id, scenario=scenario, scenario_name=scenario_name, seed=seed,
                              can_spec=spec)
    recorder.attach(session)
    return recorder


def summary_line(summary: dict) -> str:
    """One line for a process's exit report."""
    can = f", {summary['can_frames']} CAN frames to {summary['can_log']}" if summary.get("can_log") else ""
    return (f"recording: {summary['messages']} messages on {len(summary['topics'])} topics to {summary['mcap']}"
            f" ({summary['undecoded']} undecoded, {summary['dropped']} dropped){can}")
