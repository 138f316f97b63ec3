"""What the live view sends for each Zenoh sample: the record a recording writes, and the derived views.

:meth:`LiveView.convert` turns one received sample into the records to publish, each a
:class:`~sharedctl.services.recording.json_form.JsonRecord` (topic, schema, JSON body, times):
the sample as a recording writes it (``wire_record``: the message's JSON on the channel named by
its key with the JSON Schema of its kind, or ``sharedctl.Undecoded``), then its derived views
(:class:`~sharedctl.services.recording.views.DerivedViews`: ``foxglove.Log`` of an event,
``foxglove.SceneUpdate`` of a state). The same code writes recordings, so a live session and a
recording look alike. Pure: no I/O, no SDK, no clock.
"""
from __future__ import annotations

from sharedctl.protocol import keys

from ..recording.json_form import JsonRecord, wire_record
from ..recording.json_schemas import MESSAGE_SCHEMAS
from ..recording.views import DerivedViews


#: the roles whose Heartbeat channels are advertised at start (the robot's and the controller's `ROLE`): a channel
#: first advertised while a client is connected can meet that client's subscription before the server knows it
#: (the server then refuses it as an unknown channel, and the client never hears the channel); other roles' channels
#: are still made when their first heartbeat arrives
HEARTBEAT_ROLES = ("robot", "controller")


class LiveView:
    """One sample in, the records to publish out: the wire record, then the derived ones."""

    def __init__(self, views: DerivedViews) -> None:
        self.views = views

    def known_channels(self) -> list[tuple[str, str, dict]]:
        """(topic, kind, schema) of the channels known before any sample arrives: the robot's fixed keys
        (state, ground truth, operator commands, events, the heartbeats of `HEARTBEAT_ROLES`) and the derived
        views. Other roles' heartbeats and undecoded payloads get their channel when the first arrives."""
        robot = self.views.robot
        fixed = [(keys.state_key(robot), "robot_state"), (keys.truth_key(robot), "ground_truth"),
                 (keys.operator_cmd_key(robot), "operator_command"), (keys.events_key(robot), "event")]
        fixed += [(keys.alive_key(robot, role), "heartbeat") for role in HEARTBEAT_ROLES]
        return [(topic, kind, MESSAGE_SCHEMAS[kind]) for topic, kind in fixed] + self.views.channels()

    def convert(self, key: str, payload: bytes, log_ns: int, publish_ns: int | None = None) -> list[JsonRecord]:
        """The sample's record, then its derived records."""
        record = wire_record(key, payload, log_ns, publish_ns)
        return [record, *self.derive(record)]

    def derive(self, record: JsonRecord) -> list[JsonRecord]:
        """The derived records of a sample's record (none for an undecoded payload)."""
        return [] if record.message is None else self.views(record)
