"""The MCAP recording file, without processes: what the recorder writes, how a cut-short file reads, recovery.

Samples go through ``McapRecorder.put`` (what the Zenoh callback calls), so no session is opened.
"""
import base64
import json

import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader

from sharedctl.protocol import keys
from sharedctl.protocol.messages import (
    Authority, Event, EventKind, GroundTruth, Heartbeat, LinkHealth, OperatorCommand, RobotState, SetClass, Severity)
from sharedctl.protocol.msgpack_codec import encode_message, to_map
from sharedctl.services.recording.json_schemas import MESSAGE_SCHEMAS, UNDECODED_TOPIC
from sharedctl.services.recording.mcap_reading import RecordingReader, read_all
from sharedctl.services.recording.mcap_writer import McapRecorder
from sharedctl.services.recording.recover_command import recover_can_log, recover_mcap
from sharedctl.services.recording.replay_command import wire_payload

ROBOT = "robot1"
T0 = 1_790_000_000_000_000_000   # ns


def state(seq: int) -> RobotState:
    z = (0.0, 0.0, 0.0)
    return RobotState(seq=seq, time=seq * 0.02, q=(0.1 * seq, 1.0, 0.0), qd_hat=z, q_ref=z,
                      group_classes=(SetClass.SAFE, SetClass.HAZARD), active_group=0, authority=Authority.HUMAN,
                      k_s=1.0, k_h=1.0, k_f=0.0, u_h=(1.0, 2.0, 0.0), u_f=z, u_s=(1.0, 2.0, 0.0),
                      wheel_torques=z, theta_hat=(0.5, 0.25, 0.125), min_margin=0.3, region_margins=(0.3,),
                      estop_active=False, lease_holder="operator",
                      link=LinkHealth(operator_latency_ms=1.5, loss_fraction=0.0, staleness_ms=3.0,
                                      can_feedback_age_ms=0.5))


def samples():
    """(key, message) of every kind the robot's keys carry."""
    z = (0.0, 0.0, 0.0)
    out = []
    for i in range(40):
        out.append((keys.state_key(ROBOT), state(i)))
        out.append((keys.truth_key(ROBOT), GroundTruth(seq=i, time=i * 0.01, q=(0.1 * i, 1.0, 0.0), qd=z)))
        out.append((keys.operator_cmd_key(ROBOT), OperatorCommand(
            operator_id="operator", session_id="s1", seq=i, send_time=1.79e9 + i * 0.02, joystick=(0.5, 0.0, 0.0),
            q_d=(0.2 * i, 1.0, 0.0), qd_d=z, qdd_d=z, deadman=True, estop=False, control_request="none")))
    out.append((keys.events_key(ROBOT), Event(seq=0, time=1.79e9, kind=EventKind.INFO, severity=Severity.INFO,
                                              source="controller", text="hello")))
    out.append((keys.alive_key(ROBOT, "controller"), Heartbeat(role="controller", id=ROBOT, seq=0, time=1.79e9)))
    return out


def record(path, items, flush_period=0.25):
    recorder = McapRecorder(path, {"sharedctl": {"version": "test", "seed": "7"}}, flush_period=flush_period)
    for n, (key, payload) in enumerate(items):
        recorder.put(key, payload, log_time_ns=T0 + n * 1_000_000)
    return recorder


def test_every_message_is_recorded_as_its_json_map_on_its_key(tmp_path):
    items = [(k, encode_message(m)) for k, m in samples()]
    counts = record(tmp_path / "r.mcap", items).close()
    reader = make_reader(open(tmp_path / "r.mcap", "rb"))
    got = [(channel.topic, json.loads(message.data))
           for _, channel, message in reader.iter_messages(log_time_order=False)]
    assert got == [(k, json.loads(json.dumps(to_map(m)))) for k, m in samples()]
    assert counts.messages == len(items) and counts.undecoded == 0 and counts.dropped == 0


def test_derived_views_are_written_beside_their_message_and_a_failing_one_loses_nothing(tmp_path):
    from sharedctl.services.recording.views import views_for

    views = views_for(ROBOT, "paper_convex")
    calls = []

    def derive(record):
        calls.append(record.topic)
        if len(calls) == 2:
            raise RuntimeError("a view that cannot be drawn")
        return views(record)

    recorder = McapRecorder(tmp_path / "r.mcap", {}, derive=derive)
    for n, (key, message) in enumerate(samples()[:3] + samples()[-2:-1]):     # state, truth, command, event
        recorder.put(key, encode_message(message), log_time_ns=T0 + n)
    counts = recorder.close()
    messages, _ = read_all(tmp_path / "r.mcap")
    assert [(m.topic, m.schema, m.log_time) for m in messages] == [
        (keys.state_key(ROBOT), "sharedctl.RobotState", T0),
        (f"sharedctl/view/{ROBOT}/scene", "foxglove.SceneUpdate", T0),
        (keys.truth_key(ROBOT), "sharedctl.GroundTruth", T0 + 1),       # its derive call failed: the message stays
        (keys.operator_cmd_key(ROBOT), "sharedctl.OperatorCommand", T0 + 2),
        (keys.events_key(ROBOT), "sharedctl.Event", T0 + 3), (f"sharedctl/view/{ROBOT}/log", "foxglove.Log", T0 + 3)]
    assert counts.derive_errors == 1 and "cannot be drawn" in counts.derive_error
    assert json.loads(messages[-1].data)["message"] == "info: hello" and messages[-1].view
    scene = json.loads(messages[1].data)
    assert [e["id"] for e in scene["entities"]] == ["admissible_set", "robot", "reference"]


def test_channels_carry_a_jsonschema_and_json_encoding_per_kind(tmp_path):
    record(tmp_path / "r.mcap", [(k, encode_message(m)) for k, m in samples()]).close()
    summary = make_reader(open(tmp_path / "r.mcap", "rb")).get_summary()
    by_topic = {c.topic: c for c in summary.channels.values()}
    assert by_topic[keys.state_key(ROBOT)].message_encoding == "json"
    schema = summary.schemas[by_topic[keys.state_key(ROBOT)].schema_id]
    assert schema.encoding == "jsonschema" and schema.name == "sharedctl.RobotState"
    assert json.loads(schema.data) == MESSAGE_SCHEMAS["robot_state"]
    assert len(summary.channels) == 5


def test_every_schema_names_every_field_of_its_messages(tmp_path):
    for _, message in samples():
        body = to_map(message)
        schema = MESSAGE_SCHEMAS[message.KIND]
        assert set(schema["required"]) == set(body)
        assert schema["properties"]["type"]["const"] == message.KIND


def test_times_are_log_time_and_the_senders_time(tmp_path):
    key, message = samples()[2]             # an operator command: send_time
    record(tmp_path / "r.mcap", [(key, encode_message(message))]).close()
    (_, _, m), = make_reader(open(tmp_path / "r.mcap", "rb")).iter_messages()
    assert m.log_time == T0
    assert m.publish_time == int(message.send_time * 1e9)
    assert m.sequence == message.seq


def test_payloads_that_do_not_decode_are_kept_with_the_error(tmp_path):
    junk = b"\x81\xa4type\xa3bad"
    counts = record(tmp_path / "r.mcap", [(keys.events_key(ROBOT), junk)]).close()
    messages, status = read_all(tmp_path / "r.mcap")
    assert counts.undecoded == 1 and status.complete
    (m,) = messages
    body = m.json()
    assert m.topic == UNDECODED_TOPIC and body["key"] == keys.events_key(ROBOT)
    assert base64.b64decode(body["payload_base64"]) == junk and "MissingField" in body["error"]
    assert wire_payload(m) == (keys.events_key(ROBOT), junk)


def test_metadata_is_written_first(tmp_path):
    record(tmp_path / "r.mcap", []).close()
    meta = {m.name: m.metadata for m in make_reader(open(tmp_path / "r.mcap", "rb")).iter_metadata()}
    assert meta == {"sharedctl": {"version": "test", "seed": "7"}}


def test_replay_payloads_are_the_original_bytes(tmp_path):
    items = [(k, encode_message(m)) for k, m in samples()]
    record(tmp_path / "r.mcap", items).close()
    messages, _ = read_all(tmp_path / "r.mcap")
    assert [wire_payload(m) for m in messages] == items


def three_chunks(path):
    """A recording of 40 + 40 + 42 messages in three chunks (explicit flushes, no timed ones)."""
    items = [(k, encode_message(m)) for k, m in samples()]
    recorder = McapRecorder(path, {"sharedctl": {"version": "test"}}, flush_period=3600.0)
    for n, (key, payload) in enumerate(items):
        recorder.put(key, payload, log_time_ns=T0 + n)
        if n in (39, 79):
            recorder.flush()
    recorder.close()
    chunks = sorted(make_reader(open(path, "rb")).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    return items, chunks


@pytest.mark.parametrize("where, expected", [("summary", 122), ("last chunk", 80), ("second chunk", 40)])
def test_a_file_cut_short_reads_up_to_its_last_complete_chunk(tmp_path, where, expected):
    items, chunks = three_chunks(tmp_path / "r.mcap")
    assert len(chunks) == 3
    whole = (tmp_path / "r.mcap").read_bytes()
    cut = {"summary": chunks[2].chunk_start_offset + chunks[2].chunk_length + 5,
           "last chunk": chunks[2].chunk_start_offset + chunks[2].chunk_length // 2,
           "second chunk": chunks[1].chunk_start_offset + chunks[1].chunk_length // 2}[where]
    (tmp_path / "cut.mcap").write_bytes(whole[:cut])
    with pytest.raises(McapError):
        make_reader(open(tmp_path / "cut.mcap", "rb")).get_summary()   # what the indexed reader makes of it
    messages, status = read_all(tmp_path / "cut.mcap")
    assert not status.complete and status.stopped_by
    assert [wire_payload(m) for m in messages] == items[:expected]


def test_recover_rewrites_a_cut_file_as_a_complete_indexed_one(tmp_path):
    items = [(k, encode_message(m)) for k, m in samples()]
    record(tmp_path / "r.mcap", items).close()
    whole = (tmp_path / "r.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(whole[: len(whole) - 40])
    result = recover_mcap(tmp_path / "cut.mcap", tmp_path / "fixed.mcap")
    reader = make_reader(open(tmp_path / "fixed.mcap", "rb"))
    fixed = [(c.topic, m.data, m.log_time) for _, c, m in reader.iter_messages(log_time_order=False)]
    original, _ = read_all(tmp_path / "r.mcap")
    assert not result["was_complete"]
    assert fixed == [(m.topic, m.data, m.log_time) for m in original[: len(fixed)]]
    assert len(fixed) == result["messages"] and reader.get_summary().statistics.message_count == len(fixed)
    assert {m.name for m in reader.iter_metadata()} == {"sharedctl"}


def test_recover_drops_a_cut_last_line_of_a_candump_log(tmp_path):
    (tmp_path / "in.can.log").write_text("(1.000000) vcan0 00E#0000803F00000000 T\n(1.001000) vcan0 02E#00")
    result = recover_can_log(tmp_path / "in.can.log", tmp_path / "out.can.log")
    assert result == {"lines": 1, "dropped_bytes": len("(1.001000) vcan0 02E#00")}
    assert (tmp_path / "out.can.log").read_text() == "(1.000000) vcan0 00E#0000803F00000000 T\n"


def test_reader_reports_metadata_without_reading_the_messages(tmp_path):
    record(tmp_path / "r.mcap", [(k, encode_message(m)) for k, m in samples()]).close()
    assert RecordingReader(tmp_path / "r.mcap").metadata() == {"sharedctl": {"version": "test", "seed": "7"}}


def test_a_file_that_is_not_mcap_is_refused_with_a_typed_error(tmp_path):
    from sharedctl.services.recording.mcap_reading import NotARecording
    from sharedctl.services.recording.recorded_run import load_run

    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file at all")
    with pytest.raises(NotARecording):
        load_run(tmp_path / "junk.mcap")
    with pytest.raises(NotARecording):
        recover_mcap(tmp_path / "junk.mcap", tmp_path / "out.mcap")
