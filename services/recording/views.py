"""Derived views, in recordings and the live view: events as ``foxglove.Log``, states as ``foxglove.SceneUpdate``.

For each decoded message, :class:`DerivedViews` makes the records Foxglove shows natively:

* an Event → a ``foxglove.Log`` on ``sharedctl/view/<robot>/log`` (:func:`log_of`);
* a RobotState → a ``foxglove.SceneUpdate`` on ``sharedctl/view/<robot>/scene``: the admissible
  set at the robot's heading, the robot, the projected reference, and the operator's wish q_d
  from the latest OperatorCommand (:mod:`.scene`).

The view topics are outside the ``sharedctl/v1`` key space: they are views, never Zenoh keys (a
replay skips them). A recording (``McapRecorder(derive=…)``) and the live view (``sharedctl
foxglove``) use the same views, so a recording and a live session show the same channels. Pure:
no I/O, no clock (every time comes in as an argument).
"""
from __future__ import annotations

import json

from sharedctl.constraints import FeasibleSet
from sharedctl.protocol import keys
from sharedctl.protocol.messages import Event, OperatorCommand, RobotState, Severity

from ..scenario_files import load
from .foxglove_types import (LOG_DEBUG, LOG_ERROR, LOG_FATAL, LOG_INFO, LOG_SCHEMA, LOG_SCHEMA_NAME, LOG_WARNING,
                             SCENE_UPDATE_SCHEMA, SCENE_UPDATE_SCHEMA_NAME, time_of_ns)
from .json_form import JsonRecord
from .json_schemas import VIEW_PREFIX
from .scene import DEFAULT_HALF_WIDTH, scene_update

LOG_LEVELS = {Severity.DEBUG: LOG_DEBUG, Severity.INFO: LOG_INFO, Severity.WARNING: LOG_WARNING,
              Severity.ERROR: LOG_ERROR, Severity.CRITICAL: LOG_FATAL}


def log_topic(robot: str) -> str:
    return f"{VIEW_PREFIX}/{keys.check_robot_id(robot)}/log"


def scene_topic(robot: str) -> str:
    return f"{VIEW_PREFIX}/{keys.check_robot_id(robot)}/scene"


def log_of(event: Event, stamp_ns: int) -> dict:
    """An Event as a ``foxglove.Log``: stamped with its arrival (``stamp_ns``, Unix ns; the sender's own
    ``time`` may be on another clock), level from its severity, ``kind: text`` as the message, its source as name."""
    return {"timestamp": time_of_ns(stamp_ns), "level": LOG_LEVELS[event.severity],
            "message": f"{event.kind}: {event.text}", "name": event.source, "file": "", "line": 0}


def _json(body: dict) -> bytes:
    return json.dumps(body, separators=(",", ":"), allow_nan=False).encode()


class DerivedViews:
    """Event → ``foxglove.Log``; RobotState (with the latest operator command's wish) → ``foxglove.SceneUpdate``.

    Holds one piece of state: the latest q_d an OperatorCommand carried."""

    def __init__(self, robot: str, feasible: FeasibleSet | None = None, half_width: float = DEFAULT_HALF_WIDTH,
                 robot_radius: float = 0.2) -> None:
        self.robot = keys.check_robot_id(robot)
        self.feasible = feasible
        self.half_width = half_width
        self.robot_radius = robot_radius
        self.wish: tuple[float, ...] | None = None
        self.log_topic, self.scene_topic = log_topic(robot), scene_topic(robot)

    def channels(self) -> list[tuple[str, str, dict]]:
        """(topic, kind, schema) of the derived channels."""
        return [(self.log_topic, LOG_SCHEMA_NAME, LOG_SCHEMA), (self.scene_topic, SCENE_UPDATE_SCHEMA_NAME,
                                                                SCENE_UPDATE_SCHEMA)]

    def __call__(self, record: JsonRecord) -> list[JsonRecord]:
        """The derived records of one decoded message (none for most kinds)."""
        message = record.message
        if isinstance(message, OperatorCommand):
            self.wish = message.q_d
        elif isinstance(message, Event):
            return [JsonRecord(self.log_topic, LOG_SCHEMA_NAME, LOG_SCHEMA, _json(log_of(message, record.log_time)),
                               record.log_time, record.publish_time, record.sequence)]
        elif isinstance(message, RobotState):
            body = scene_update(message, record.log_time, self.feasible, self.wish, self.half_width,
                                self.robot_radius)
            return [JsonRecord(self.scene_topic, SCENE_UPDATE_SCHEMA_NAME, SCENE_UPDATE_SCHEMA, _json(body),
                               record.log_time, record.publish_time, record.sequence)]
        return []


def robot_radius(model) -> float:
    """The drawn robot's radius: wheel distance plus wheel radius for the omnidirectional robot, else 0.1 m."""
    parameters = getattr(model, "parameters", None)
    try:
        return float(parameters.wheel_distance + parameters.wheel_radius)
    except AttributeError:
        return 0.1


def views_for(robot: str, scenario: str | None, half_width: float = DEFAULT_HALF_WIDTH) -> DerivedViews:
    """The views of `robot` running `scenario` (file or packaged name): its admissible set and the robot's size.
    Without a scenario the scene has no set; one that does not load raises ScenarioError (a ValueError)."""
    if scenario is None:
        return DerivedViews(robot, None, half_width)
    loop, _, _ = load(scenario).closed_loop(None)
    return DerivedViews(robot, loop.feasible, half_width, robot_radius(loop.model))
