"""The live view's conversions, against values computed by hand: the set's slice at the robot's heading,
foxglove.Log of an event, the SceneUpdate's robot, reference and wish, the listen address, and a
publisher that survives malformed payloads and failing conversions."""
import json
import math

import foxglove
import pytest

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.protocol import keys
from sharedctl.protocol import messages as m
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.services import cli
from sharedctl.services.foxglove.address import AddressError, listen_address
from sharedctl.services.foxglove.bridge import LiveView
from sharedctl.services.foxglove.command import Publisher
from sharedctl.services.recording.foxglove_types import pose, time_of_ns
from sharedctl.services.recording.scene import region_slice, scene_update
from sharedctl.services.recording.views import DerivedViews, log_of
from sharedctl.services.scenario_files import load

HALF_PI = math.pi / 2
ROBOT = "robot1"
T0 = 1_700_000_000_250_000_000        # ns


def feasible_of(name: str) -> FeasibleSet:
    return load(name).closed_loop(None)[0].feasible


def area(piece) -> float:
    """Shoelace formula over the slice's vertices."""
    v = piece.vertices
    return 0.5 * abs(sum(v[i][0] * v[(i + 1) % len(v)][1] - v[(i + 1) % len(v)][0] * v[i][1] for i in range(len(v))))


def segments(piece) -> set:
    return {frozenset((tuple(round(c, 9) + 0.0 for c in a), tuple(round(c, 9) + 0.0 for c in b)))
            for a, b, _ in piece.faces()}


def state(**changes) -> m.RobotState:
    fields = dict(seq=1, time=2.0, q=(0.5, 1.5, 0.25), qd_hat=(0.0, 0.0, 0.0), q_ref=(0.4, 1.4, 0.2),
                  group_classes=(m.SetClass.SAFE,), active_group=0, authority=m.Authority.MACHINE, k_s=0.0,
                  k_h=0.0, k_f=1.0, u_h=(0.0, 0.0, 0.0), u_f=(0.0, 0.0, 0.0), u_s=(0.0, 0.0, 0.0),
                  wheel_torques=(0.0, 0.0, 0.0), theta_hat=(1.0, 2.0, 3.0), min_margin=0.5, region_margins=(0.5,),
                  estop_active=False, lease_holder="alice",
                  link=m.LinkHealth(operator_latency_ms=1.0, loss_fraction=0.0, staleness_ms=1.0,
                                    can_feedback_age_ms=1.0))
    fields.update(changes)
    return m.RobotState(**fields)


def command(q_d) -> m.OperatorCommand:
    return m.OperatorCommand(operator_id="alice", session_id="s-1", seq=3, send_time=100.0, joystick=(0.0, 0.0, 0.0),
                             q_d=q_d, qd_d=(0.0, 0.0, 0.0), qdd_d=(0.0, 0.0, 0.0), deadman=True, estop=False,
                             control_request=m.ControlRequest.NONE)


def event(severity=m.Severity.WARNING) -> m.Event:
    return m.Event(seq=4, time=12.0, kind=m.EventKind.ESTOP, severity=severity, source="controller",
                   text="operator estop")


# ----- the set's slice ------------------------------------------------------------------
def test_the_convex_papers_set_is_the_rectangle_inside_the_window_with_three_faces():
    # x ≥ −1, 0.5 ≤ y ≤ 4, |ψ| < π/2; window around (0, 2) of half-width 4: x ∈ [−4, 4], y ∈ [−2, 6]
    (region,) = feasible_of("paper_convex").regions
    piece = region_slice(region, (0.0, 2.0, 0.0), 4.0)
    assert area(piece) == pytest.approx(5.0 * 3.5)
    assert segments(piece) == {frozenset({(-1.0, 0.5), (-1.0, 4.0)}), frozenset({(-1.0, 0.5), (4.0, 0.5)}),
                               frozenset({(-1.0, 4.0), (4.0, 4.0)})}     # x = 4 is the window's edge, no face


def test_a_heading_outside_the_yaw_bounds_empties_the_region():
    (region,) = feasible_of("paper_convex").regions
    assert region_slice(region, (0.0, 2.0, HALF_PI + 0.1), 4.0).empty
    entity = scene_update(state(q=(0.0, 2.0, 2.0)), T0, feasible_of("paper_convex"))["entities"][0]
    assert entity["id"] == "admissible_set" and entity["triangles"] == [] and entity["lines"] == []


def test_a_face_that_depends_on_the_heading_moves_with_it():
    # x + ψ ≤ 1, x ≥ −1, |y| ≤ 1: at ψ = 0.5 the slice is x ∈ [−1, 0.5], y ∈ [−1, 1]
    region = Polytope.from_rows([[1, 0, 1], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], [-1, -1, -1, -1])
    piece = region_slice(region, (0.0, 0.0, 0.5), 3.0)
    assert area(piece) == pytest.approx(1.5 * 2.0)
    assert frozenset({(0.5, -1.0), (0.5, 1.0)}) in segments(piece)
    assert area(region_slice(region, (0.0, 0.0, 1.5), 3.0)) == pytest.approx(0.5 * 2.0)


def test_each_region_of_the_non_convex_set_is_sliced_on_its_own():
    # x ≤ 0 or y ≤ 0; window around (−0.5, −0.5) of half-width 1: x, y ∈ [−1.5, 0.5]
    first, second = feasible_of("paper_nonconvex").regions
    assert area(region_slice(first, (-0.5, -0.5, 0.0), 1.0)) == pytest.approx(1.5 * 2.0)
    assert area(region_slice(second, (-0.5, -0.5, 0.0), 1.0)) == pytest.approx(2.0 * 1.5)
    assert segments(region_slice(first, (-0.5, -0.5, 0.0), 1.0)) == {frozenset({(0.0, -1.5), (0.0, 0.5)})}


def test_the_fill_triangles_cover_the_slice():
    update = scene_update(state(q=(0.0, 2.0, 0.0)), T0, feasible_of("paper_convex"), half_width=4.0)
    fill = update["entities"][0]["triangles"][0]["points"]
    assert len(fill) % 3 == 0
    total = sum(0.5 * abs((b["x"] - a["x"]) * (c["y"] - a["y"]) - (c["x"] - a["x"]) * (b["y"] - a["y"]))
                for a, b, c in zip(fill[::3], fill[1::3], fill[2::3]))
    assert total == pytest.approx(17.5)


# ----- the scene's robot, reference and wish ------------------------------------------------
def test_the_robot_the_reference_and_the_wish_stand_where_the_messages_put_them():
    views = DerivedViews(ROBOT, feasible_of("paper_convex"))
    view = LiveView(views)
    assert len(view.convert(keys.operator_cmd_key(ROBOT), encode_message(command((1.0, 2.5, 0.0))), T0)) == 1
    wire, scene = view.convert(keys.state_key(ROBOT), encode_message(state()), T0 + 5)
    assert wire.topic == keys.state_key(ROBOT) and wire.schema_name == "sharedctl.RobotState"
    assert scene.topic == f"sharedctl/view/{ROBOT}/scene" and scene.schema_name == "foxglove.SceneUpdate"
    assert scene.log_time == T0 + 5
    entities = {e["id"]: e for e in json.loads(scene.data)["entities"]}
    robot = entities["robot"]
    assert robot["cylinders"][0]["pose"]["position"] == {"x": 0.5, "y": 1.5, "z": 0.025}
    assert robot["arrows"][0]["pose"]["orientation"]["z"] == pytest.approx(math.sin(0.125))
    assert robot["cylinders"][0]["color"] == {"r": 0.90, "g": 0.20, "b": 0.15, "a": 1.0}   # machine
    assert entities["reference"]["spheres"][0]["pose"]["position"]["x"] == 0.4
    assert (entities["wish"]["spheres"][0]["pose"]["position"]["x"],
            entities["wish"]["spheres"][0]["pose"]["position"]["y"]) == (1.0, 2.5)
    assert robot["timestamp"] == {"sec": 1_700_000_000, "nsec": 250_000_005}


def test_no_wish_is_drawn_before_an_operator_command():
    view = LiveView(DerivedViews(ROBOT, feasible_of("paper_convex")))
    _, scene = view.convert(keys.state_key(ROBOT), encode_message(state()), T0)
    assert [e["id"] for e in json.loads(scene.data)["entities"]] == ["admissible_set", "robot", "reference"]


# ----- events as foxglove.Log ---------------------------------------------------------------
@pytest.mark.parametrize("severity,level", [(m.Severity.DEBUG, 1), (m.Severity.INFO, 2), (m.Severity.WARNING, 3),
                                            (m.Severity.ERROR, 4), (m.Severity.CRITICAL, 5)])
def test_an_event_is_a_log_at_its_severity_stamped_on_arrival(severity, level):
    assert log_of(event(severity), T0) == {"timestamp": {"sec": 1_700_000_000, "nsec": 250_000_000}, "level": level,
                                           "message": "estop: operator estop", "name": "controller", "file": "",
                                           "line": 0}


def test_an_event_sample_gives_its_record_and_a_log():
    records = LiveView(DerivedViews(ROBOT)).convert(keys.events_key(ROBOT), encode_message(event()), T0)
    assert [r.topic for r in records] == [keys.events_key(ROBOT), f"sharedctl/view/{ROBOT}/log"]
    assert json.loads(records[1].data)["level"] == 3


def test_times_and_headings_in_foxglove_form():
    assert time_of_ns(T0) == {"sec": 1_700_000_000, "nsec": 250_000_000}
    assert pose(yaw=HALF_PI)["orientation"] == pytest.approx({"x": 0.0, "y": 0.0, "z": math.sqrt(0.5),
                                                              "w": math.sqrt(0.5)})


# ----- malformed input ------------------------------------------------------------------
def test_a_malformed_payload_is_an_undecoded_record_and_nothing_is_derived():
    records = LiveView(DerivedViews(ROBOT)).convert(keys.state_key(ROBOT), b"\x93\x01\x02", T0)
    assert [r.topic for r in records] == ["sharedctl/undecoded"]
    body = json.loads(records[0].data)
    assert body["key"] == keys.state_key(ROBOT) and body["size"] == 3 and body["error"]


def test_the_publisher_counts_bad_samples_and_goes_on():
    publisher = Publisher(LiveView(DerivedViews(ROBOT, feasible_of("paper_convex"))), foxglove.Context())
    try:
        publisher.publish(keys.state_key(ROBOT), b"\xc1", T0, None)                      # not MessagePack
        publisher.view.views.feasible = "not a set"                                   # the scene cannot be made
        publisher.publish(keys.state_key(ROBOT), encode_message(state()), T0, None)
        publisher.publish(keys.events_key(ROBOT), encode_message(event()), T0, None)
    finally:
        counts = publisher.close()
    assert counts.undecoded == 1 and counts.errors == 1
    assert counts.per_topic == {"sharedctl/undecoded": 1, keys.state_key(ROBOT): 1, keys.events_key(ROBOT): 1,
                                f"sharedctl/view/{ROBOT}/log": 1}


# ----- the WebSocket address ---------------------------------------------------------------
@pytest.mark.parametrize("text,expected", [("127.0.0.1:8765", ("127.0.0.1", 8765)), ("[::1]:0", ("::1", 0)),
                                           ("localhost:9000", ("localhost", 9000)), ("127.1.2.3:1", ("127.1.2.3", 1))])
def test_loopback_addresses_are_served(text, expected):
    assert listen_address(text) == expected


@pytest.mark.parametrize("text", ["0.0.0.0:8765", "192.168.1.5:8765", "[::]:8765"])
def test_other_hosts_only_when_allowed(text):
    with pytest.raises(AddressError, match="not a loopback address"):
        listen_address(text)
    assert listen_address(text, allow_remote=True)[1] == 8765


@pytest.mark.parametrize("text", ["8765", "127.0.0.1", "127.0.0.1:port", "127.0.0.1:70000", "example.com:80"])
def test_malformed_addresses_are_refused(text):
    with pytest.raises(AddressError):
        listen_address(text)


def test_the_demo_refuses_a_live_view_on_another_host(capsys):
    assert cli.main(["demo", "--foxglove", "0.0.0.0:8765"]) == 2
    assert "--foxglove '0.0.0.0:8765': not a loopback address" in capsys.readouterr().err


# ----- the layout --------------------------------------------------------------------------
def test_the_layout_in_deploy_is_the_one_the_command_writes(tmp_path):
    from pathlib import Path

    from sharedctl.services.foxglove.layout import layout_json

    shipped = Path(__file__).resolve().parents[2] / "deploy" / "foxglove" / "sharedctl-layout.json"
    assert shipped.read_text() == layout_json(ROBOT)
    assert cli.main(["foxglove", "--write-layout", str(tmp_path / "l.json"), "--robot-id", "robot7"]) == 0
    assert "sharedctl/v1/robot7/state" in (tmp_path / "l.json").read_text()


def test_every_topic_the_layout_shows_is_a_channel_the_live_view_serves():
    from sharedctl.services.foxglove.layout import layout_json

    panels, topics = [], set()

    def walk(node):
        if isinstance(node, dict):
            if node.get("type") == "panel":
                panels.append(node["panelType"])
            for key, value in node.items():
                if key in ("value", "topicPath", "topicToRender") and isinstance(value, str):
                    topics.add(value.split(".")[0])
                elif key == "topics":
                    topics.update(value)
                walk(value)
        elif isinstance(node, list):
            for item in node:
                walk(item)

    walk(json.loads(layout_json(ROBOT)))
    served = {topic for topic, _, _ in LiveView(DerivedViews(ROBOT)).known_channels()}
    assert topics and topics <= served, topics - served
    assert {"ThreeDee", "Plot", "StateTransitions", "Log", "RawMessages"} <= set(panels)
    assert f"sharedctl/view/{ROBOT}/scene" in topics and f"sharedctl/view/{ROBOT}/log" in topics


def test_the_command_refuses_another_host_without_allow_remote_before_serving(capsys):
    assert cli.main(["foxglove", "--connect", "tcp/127.0.0.1:7447", "--listen", "0.0.0.0:8765"]) == 2
    assert "not a loopback address" in capsys.readouterr().err
    assert cli.main(["foxglove", "--listen", "127.0.0.1:8765"]) == 2          # no Zenoh endpoint at all
    assert cli.main(["foxglove", "--connect", "tcp/192.168.1.2:7447"]) == 2    # Zenoh stays on loopback too


def test_the_robots_and_the_controllers_heartbeats_are_advertised_before_any_arrives():
    from sharedctl.services.controller.daemon import ROLE as CONTROLLER
    from sharedctl.services.robot.process import ROLE as ROBOT_ROLE

    known = {(topic, kind) for topic, kind, _ in LiveView(DerivedViews(ROBOT)).known_channels()}
    assert {(keys.alive_key(ROBOT, role), "heartbeat") for role in (ROBOT_ROLE, CONTROLLER)} <= known
