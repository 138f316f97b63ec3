"""The live view end to end: `sharedctl demo --headless --foxglove 127.0.0.1:PORT` serves a Foxglove client.

The client is the `websockets` library speaking the Foxglove WebSocket protocol by hand (subprotocol
``foxglove.sdk.v1``, which foxglove-sdk 0.30 serves), independent of the SDK that serves it: it
receives ``serverInfo`` and ``advertise``, subscribes to every channel as it is advertised, and reads
binary ``messageData`` frames (opcode 1: subscription id u32, log time u64, payload) until the demo
ends and the server closes. Every advertised channel delivers live messages whose JSON decodes and
whose content is sane, the wire channels carry the recordings' schemas, and the scene's robot
stands where the RobotState served at the same instant puts it, inside the paper's convex set.
"""
import asyncio
import json
import math
import struct
import subprocess
import sys
import time

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from sharedctl.protocol import keys
from sharedctl.services.recording.json_schemas import MESSAGE_SCHEMAS, schema_bytes
from sharedctl.services.zenoh_session import free_loopback_port

from .processes import reap

pytestmark = pytest.mark.processes
SUBPROTOCOL = "foxglove.sdk.v1"
ROBOT = "robot1"
DURATION = 4.0
FEEDBACK_TIMEOUT = ("--feedback-timeout-ms", "150")   # as in test_demo_e2e: a loaded 2-core host
WIRE_TOPICS = {keys.state_key(ROBOT): "robot_state", keys.truth_key(ROBOT): "ground_truth",
               keys.operator_cmd_key(ROBOT): "operator_command", keys.events_key(ROBOT): "event",
               keys.alive_key(ROBOT, "controller"): "heartbeat", keys.alive_key(ROBOT, "robot"): "heartbeat"}
LOG, SCENE = f"sharedctl/view/{ROBOT}/log", f"sharedctl/view/{ROBOT}/scene"
# paper_convex: x ≥ −1, 0.5 ≤ y ≤ 4 (sharedctl/scenarios/paper_convex.toml)
CONVEX_SET = (-1.0, 0.5, 4.0)


async def _watch(port: int, timeout: float, running) -> dict:
    """Everything a Foxglove client hears from the server until it closes (or `timeout` passes)."""
    deadline = time.monotonic() + timeout
    while True:                                   # the server comes up once the demo has started it
        try:
            ws = await connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], max_size=None,
                               open_timeout=2)
            break
        except (OSError, asyncio.TimeoutError):
            if time.monotonic() > deadline or not running():
                raise
            await asyncio.sleep(0.1)
    heard = {"subprotocol": ws.subprotocol, "server_info": None, "channels": {}, "messages": {}, "stray": 0}
    subscriptions: dict[int, int] = {}             # our subscription id -> channel id
    try:
        while time.monotonic() < deadline:
            try:
                frame = await asyncio.wait_for(ws.recv(), max(0.1, deadline - time.monotonic()))
            except (ConnectionClosed, asyncio.TimeoutError):
                break
            if isinstance(frame, str):
                op = json.loads(frame)
                if op["op"] == "serverInfo":
                    heard["server_info"] = op
                elif op["op"] == "advertise":
                    new = []
                    for channel in op["channels"]:
                        if channel["id"] not in heard["channels"]:
                            heard["channels"][channel["id"]] = channel
                            subscriptions[len(subscriptions) + 1] = channel["id"]
                            new.append({"id": len(subscriptions), "channelId": channel["id"]})
                    if new:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            elif frame[0] == 1:                    # messageData
                subscription, log_time = struct.unpack_from("<IQ", frame, 1)
                channel = subscriptions.get(subscription)
                if channel is None:
                    heard["stray"] += 1
                else:
                    heard["messages"].setdefault(channel, []).append((log_time, bytes(frame[13:])))
    finally:
        await ws.close()
    return heard


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    out = tmp_path_factory.mktemp("foxglove-live")
    port = free_loopback_port()
    summary_path = out / "demo.json"
    with open(out / "demo.out", "wb") as log:
        demo = subprocess.Popen(
            [sys.executable, "-m", "sharedctl.services.cli", "demo", "--headless", "--foxglove", f"127.0.0.1:{port}",
             "--duration", str(DURATION), "--no-reference", "--json", str(summary_path), "--log-dir", str(out / "logs"),
             *FEEDBACK_TIMEOUT],
            stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT)
    try:
        heard = asyncio.run(_watch(port, 60.0, lambda: demo.poll() is None))
        demo.wait(timeout=30)
    finally:
        reap([demo])
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    assert summary, (out / "demo.out").read_text()
    by_topic = {channel["topic"]: (channel, [json.loads(data) for _, data in heard["messages"].get(cid, [])],
                                   [t for t, _ in heard["messages"].get(cid, [])])
                for cid, channel in heard["channels"].items()}
    return heard, by_topic, summary


def test_the_demo_with_the_live_view_runs_and_stops_it_cleanly(live):
    _, _, summary = live
    assert summary["ok"], summary.get("failure")
    viewer = summary["processes"]["foxglove"]
    assert viewer["exit_code"] == 0 and not viewer["killed"]
    assert viewer["summary"]["errors"] == 0 and viewer["summary"]["undecoded"] == 0


def test_the_client_gets_server_info_and_every_channel_advertised(live):
    heard, by_topic, _ = live
    assert heard["subprotocol"] == SUBPROTOCOL
    assert heard["server_info"]["name"] == f"sharedctl {ROBOT}"
    assert set(WIRE_TOPICS) | {LOG, SCENE} <= set(by_topic), sorted(by_topic)
    assert heard["stray"] == 0


def test_every_advertised_channel_delivers_live_json_messages(live):
    _, by_topic, _ = live
    for topic, (channel, bodies, _) in by_topic.items():
        assert channel["encoding"] == "json" and channel["schemaEncoding"] == "jsonschema", channel
        assert bodies, f"nothing received on {topic}"
    for topic, (_, bodies, _) in by_topic.items():
        assert len(bodies) > (1 if topic in (LOG, keys.events_key(ROBOT)) or "/alive/" in topic else 20), topic


def test_the_wire_channels_carry_the_recordings_schemas(live):
    _, by_topic, _ = live
    for topic, kind in WIRE_TOPICS.items():
        channel, bodies, _ = by_topic[topic]
        assert channel["schemaName"] == MESSAGE_SCHEMAS[kind]["title"]
        assert channel["schema"].encode() == schema_bytes(MESSAGE_SCHEMAS[kind])
        assert {body["type"] for body in bodies} == {kind}


def test_state_truth_and_commands_are_sane(live):
    _, by_topic, _ = live
    for topic, field in ((keys.state_key(ROBOT), "q"), (keys.truth_key(ROBOT), "q"),
                         (keys.operator_cmd_key(ROBOT), "q_d")):
        for body in by_topic[topic][1]:
            assert len(body[field]) == 3 and all(math.isfinite(v) for v in body[field]), (topic, body)
    states = by_topic[keys.state_key(ROBOT)][1]
    assert {s["authority"] for s in states} <= {"human", "shared", "machine"}
    assert all(s["min_margin"] > 0.0 for s in states)
    assert any(s["lease_holder"] for s in states)       # the scripted operator drove


def test_events_arrive_as_foxglove_logs(live):
    _, by_topic, _ = live
    events, logs = by_topic[keys.events_key(ROBOT)][1], by_topic[LOG][1]
    assert by_topic[LOG][0]["schemaName"] == "foxglove.Log"
    assert len(logs) == len(events)
    for event, log in zip(events, logs):
        assert log["level"] in (1, 2, 3, 4, 5) and log["name"] == event["source"]
        assert log["message"] == f"{event['kind']}: {event['text']}"
        assert log["timestamp"]["sec"] > 1_600_000_000 and 0 <= log["timestamp"]["nsec"] < 1_000_000_000


def test_the_scene_draws_the_set_the_robot_the_reference_and_the_wish(live):
    _, by_topic, _ = live
    channel, scenes, scene_times = by_topic[SCENE]
    assert channel["schemaName"] == "foxglove.SceneUpdate"
    _, states, state_times = by_topic[keys.state_key(ROBOT)]
    state_at = dict(zip(state_times, states))
    matched = 0
    x_min, y_min, y_max = CONVEX_SET
    for t, scene in zip(scene_times, scenes):
        entities = {e["id"]: e for e in scene["entities"]}
        assert {"admissible_set", "robot", "reference"} <= set(entities)
        corners = [p for tri in entities["admissible_set"]["triangles"] for p in tri["points"]]
        assert corners and all(p["x"] >= x_min - 1e-9 and y_min - 1e-9 <= p["y"] <= y_max + 1e-9 for p in corners)
        assert any(abs(p["x"] - x_min) < 1e-9 for p in corners)      # the face x = −1 is in the window
        if t in state_at:                           # the RobotState served at the same instant
            where = entities["robot"]["cylinders"][0]["pose"]["position"]
            q = state_at[t]["q"]
            assert (where["x"], where["y"]) == pytest.approx((q[0], q[1]), abs=1e-12)
            reference = entities["reference"]["spheres"][0]["pose"]["position"]
            assert (reference["x"], reference["y"]) == pytest.approx(tuple(state_at[t]["q_ref"][:2]), abs=1e-12)
            matched += 1
    assert matched > 20
    assert any("wish" in {e["id"] for e in scene["entities"]} for scene in scenes)
