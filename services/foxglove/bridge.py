"""What the live view sends for each Zenoh sample: the recording's JSON record, and the derived views.

:meth:`LiveView.convert` turns one received sample into the records to publish, each a
:class:`~sharedctl.services.recording.json_form.JsonRecord` (topic, schema, JSON body, times):

* the sample itself as a recording writes it (``wire_record``: the message's JSON on the channel
  named by its key with the JSON Schema of its kind, or ``sharedctl.Undecoded``);
* an Event also as a ``foxglove.Log`` on ``sharedctl/view/<robot>/log`` (:func:`log_of`);
* a RobotState also as a ``foxglove.SceneUpdate`` on ``sharedctl/view/<robot>/scene``: the
  admissible set at the robot's heading, the robot, the projected reference, and the operator's
  wish q_d from the latest OperatorCommand (:mod:`.scene`).

The derived topics are outside the ``sharedctl/v1`` key space: they are views, never Zenoh keys
(a replay skips them). A recording made with the same :class:`DerivedViews` holds the same
channels. Pure: no I/O, no SDK, no clock (every time comes in as an argument).
"""
from __future__ import annotations

import json

from sharedctl.constraints import FeasibleSet
from sharedctl.protocol import keys
from sharedctl.protocol.messages import Event, OperatorCommand, RobotState, Severity

from ..recording.json_form import JsonRecord, wire_record
from ..recording.json_schemas import MESSAGE_SCHEMAS
from .scene import DEFAULT_HALF_WIDTH, scene_update
from .wellknown import (LOG_DEBUG, LOG_ERROR, LOG_FATAL, LOG_INFO, LOG_SCHEMA, LOG_SCHEMA_NAME, LOG_WARNING,
                        SCENE_UPDATE_SCHEMA, SCENE_UPDATE_SCHEMA_NAME, time_of_ns)

VIEW_PREFIX = f"{keys.ROOT}/view"
LOG_LEVELS = {Severity.DEBUG: LOG_DEBUG, Severity.INFO: LOG_INFO, Severity.WARNING: LOG_WARNING,
              Severity.ERROR: LOG_ERROR, Severity.CRITICAL: LOG_FATAL}


def log_topic(robot: str) -> str:
    return f"{VIEW_PREFIX}/{keys.check_robot_id(robot)}/log"


def scene_topic(robot: str) -> str:
    return f"{VIEW_PREFIX}/{keys.check_robot_id(robot)}/scene"


def is_view_topic(topic: str) -> bool:
    """A derived view's topic (not a Zenoh key)."""
    return topic.startswith(VIEW_PREFIX + "/")


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


class LiveView:
    """One sample in, the records to publish out: the wire record, then the derived ones."""

    def __init__(self, views: DerivedViews) -> None:
        self.views = views

    def known_channels(self) -> list[tuple[str, str, dict]]:
        """(topic, kind, schema) of the channels known before any sample arrives: the robot's fixed keys
        (state, ground truth, operator commands, events) and the derived views. Heartbeats (one key per
        role) and undecoded payloads get their channel when the first arrives."""
        robot = self.views.robot
        fixed = [(keys.state_key(robot), "robot_state"), (keys.truth_key(robot), "ground_truth"),
                 (keys.operator_cmd_key(robot), "operator_command"), (keys.events_key(robot), "event")]
        return [(topic, kind, MESSAGE_SCHEMAS[kind]) for topic, kind in fixed] + self.views.channels()

    def convert(self, key: str, payload: bytes, log_ns: int, publish_ns: int | None = None) -> list[JsonRecord]:
        """The sample's record, then its derived records."""
        record = wire_record(key, payload, log_ns, publish_ns)
        return [record, *self.derive(record)]

    def derive(self, record: JsonRecord) -> list[JsonRecord]:
        """The derived records of a sample's record (none for an undecoded payload)."""
        return [] if record.message is None else self.views(record)
