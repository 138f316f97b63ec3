"""The metrics endpoint over HTTP: the exporter in this process, then `sharedctl robot` and `sharedctl
controller` with `--metrics`, scraped with urllib and read with prometheus_client's parser."""
from __future__ import annotations

import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request

import pytest
from prometheus_client.parser import text_string_to_metric_families

from sharedctl.protocol import keys
from sharedctl.protocol.messages import ControlRequest, OperatorCommand
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.services import zenoh_session
from sharedctl.services.metrics import MetricsAddress, serve
from sharedctl.services.robot.metrics import RobotCollector
from sharedctl.services.summary_output import read_json

from .processes import reap, wait_for
from .test_controller_with_robot import free_udp_port
from .test_robot_metrics import process_with

pytestmark = pytest.mark.processes   # sockets and processes: never in a parallel worker


def scrape(url: str) -> dict:
    """{(sample name, frozenset(labels)): value} of one GET of `url`."""
    with urllib.request.urlopen(url, timeout=2.0) as response:
        text = response.read().decode()
    return {(s.name, frozenset(s.labels.items())): s.value
            for family in text_string_to_metric_families(text) for s in family.samples}


def try_scrape(url: str) -> dict:
    try:
        return scrape(url)
    except OSError:
        return {}


def refused(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) != 0


def test_the_exporter_binds_a_free_port_serves_its_registry_and_frees_the_port_when_closed():
    process = process_with([])
    process.sim.steps = 17
    server = serve(MetricsAddress("127.0.0.1", 0), RobotCollector(process),
                   thread_setup=lambda: threading.current_thread().name)
    try:
        assert server.setup_result == "metrics"                          # ran in the server's own thread
        assert server.port > 0 and server.url == f"http://127.0.0.1:{server.port}/metrics"
        samples = scrape(server.url)
        assert samples[("sharedctl_robot_physics_steps_total", frozenset())] == 17
        assert samples[("process_cpu_seconds_total", frozenset())] > 0     # the process collector, registered
        assert not any(name.startswith("python_gc_") for name, _ in samples)   # and no other default one
    finally:
        server.close()
    assert not server.thread.is_alive() and refused(server.port)


def test_requests_are_served_one_at_a_time_at_most_one_per_min_interval():
    """A local client hammering the endpoint cannot take the interpreter from the loop more than that."""
    server = serve(MetricsAddress("127.0.0.1", 0), RobotCollector(process_with([])), min_interval=0.1)
    try:
        started = time.monotonic()
        for _ in range(4):
            scrape(server.url)
        assert time.monotonic() - started >= 0.3
    finally:
        server.close()


def value(samples: dict, name: str, **labels) -> float:
    return samples.get((name, frozenset(labels.items())), 0.0)


def test_robot_and_controller_serve_their_loops_lease_and_rejections_and_close_the_port_at_exit(tmp_path):
    can_port, z_robot, z_ctrl = free_udp_port(), zenoh_session.free_loopback_port(), zenoh_session.free_loopback_port()
    m_robot, m_ctrl = zenoh_session.free_loopback_port(), zenoh_session.free_loopback_port()
    can_args = ["--can-interface", "udp_multicast", "--can-option", f"port={can_port}", "--robot-id", "mtest"]
    cli = [sys.executable, "-m", "sharedctl.services.cli"]
    procs = [
        subprocess.Popen(["nice", "-n", "-10", *cli, "robot", *can_args, "--zenoh-listen", f"tcp/127.0.0.1:{z_robot}",
                          "--metrics", f"127.0.0.1:{m_robot}"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True),
        subprocess.Popen([*cli, "controller", *can_args, "--zenoh-listen", f"tcp/127.0.0.1:{z_ctrl}", "--quiet",
                          "--feedback-timeout-ms", "150", "--metrics", str(m_ctrl),
                          "--json", str(tmp_path / "controller.json")],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True),
    ]
    robot, controller = procs
    robot_url, ctrl_url = f"http://127.0.0.1:{m_robot}/metrics", f"http://127.0.0.1:{m_ctrl}/metrics"
    session = zenoh_session.open_session(connect=[f"tcp/127.0.0.1:{z_ctrl}"])
    try:
        C, R = "sharedctl_controller_", "sharedctl_robot_"
        wait_for(lambda: value(try_scrape(ctrl_url), C + "mode", mode="running") == 1, 20.0, "the controller armed",
                 poll=0.2)
        first, first_robot, t1 = scrape(ctrl_url), scrape(robot_url), time.monotonic()
        time.sleep(1.5)
        second, second_robot, t2 = scrape(ctrl_url), scrape(robot_url), time.monotonic()
        ticks = value(second, C + "ticks_total") - value(first, C + "ticks_total")
        skipped = (value(second, C + "deadline_misses_total", kind="skipped")
                   - value(first, C + "deadline_misses_total", kind="skipped"))
        assert ticks > 0
        assert abs(ticks + skipped - 500.0 * (t2 - t1)) < 0.05 * 500.0 * (t2 - t1) + 10   # every deadline, once
        assert value(second, C + "loop_rate_hertz") == 500.0
        assert 250.0 < value(second, C + "loop_achieved_rate_hertz") <= 505.0
        assert value(second, C + "feedback_age_seconds") < 0.15
        steps = value(second_robot, R + "physics_steps_total") - value(first_robot, R + "physics_steps_total")
        assert steps > 0.5 * 1000.0 * (t2 - t1)
        assert value(second_robot, R + "can_frames_received_total") > 0
        assert value(second, C + "lease_held") == 0

        pub = session.declare_publisher(keys.operator_cmd_key("mtest"))

        def command(seq: int) -> bytes:
            return encode_message(OperatorCommand(
                operator_id="itester", session_id="m1", seq=seq, send_time=time.time(), joystick=(0.0, 0.0, 0.0),
                q_d=(-0.9, 3.0, 0.0), qd_d=(0.0, 0.0, 0.0), qdd_d=(0.0, 0.0, 0.0), deadman=True, estop=False,
                control_request=ControlRequest.NONE))
        for seq in range(1, 6):
            pub.put(command(seq))
            time.sleep(0.02)
        wait_for(lambda: value(try_scrape(ctrl_url), C + "lease_holder_info", operator="itester") == 1, 5.0,
                 "the operator as the lease holder", poll=0.1)
        pub.put(command(3))                                              # a replay
        wait_for(lambda: value(try_scrape(ctrl_url), C + "rejected_messages_total", reason="out_of_order_seq") == 1,
                 5.0, "the replay counted by its reason", poll=0.1)

        for proc in (controller, robot):
            proc.send_signal(signal.SIGTERM)
            _, err = proc.communicate(timeout=5)
            assert proc.returncode == 0, err
        assert refused(m_ctrl) and refused(m_robot)
        assert read_json(tmp_path / "controller.json")["metrics_url"] == ctrl_url
    finally:
        session.close()
        reap(procs)
