"""A recorder killed with SIGKILL mid-run: its files keep everything up to ~1 s before the kill.

`sharedctl record` listens for Zenoh and logs a host-local udp_multicast CAN bus; this test
publishes GroundTruth at ~100 Hz and sends a CAN frame with each, kills the recorder with
SIGKILL while that goes on, and reads what is left: the MCAP file (no summary, no footer) with
the sequential reader, the candump log with python-can — then `record-recover` makes the MCAP
file whole for the indexed reader.
"""
import os
import signal
import socket
import subprocess
import sys
import time

import can
import pytest
from mcap.reader import make_reader

from sharedctl.protocol import cansimple, keys
from sharedctl.protocol.messages import GroundTruth
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.services import can_bus
from sharedctl.services.children import free_udp_port
from sharedctl.services.recording.json_schemas import UNDECODED_TOPIC
from sharedctl.services.recording.mcap_reading import read_all
from sharedctl.services.recording.recover_command import recover_can_log, recover_mcap
from sharedctl.services.zenoh_session import free_loopback_port, open_session
from .processes import reap, wait_for

pytestmark = pytest.mark.processes
ROBOT = "robot1"
PROMISE = 1.0          # s: at most this much of what was sent before the kill may be missing
PUBLISH_BEFORE_KILL = 2.0
JUNK = b"\xc1not msgpack"


def accepting(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


@pytest.fixture(scope="module")
def killed_recording(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("killed-recorder")
    port, udp_port = free_loopback_port(), free_udp_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    recorder = subprocess.Popen(
        [sys.executable, "-m", "sharedctl.services.cli", "record", "--out", str(tmp_path), "--zenoh-listen", endpoint,
         "--can-interface", "udp_multicast", "--can-option", f"port={udp_port}"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    session = bus = None
    try:
        wait_for(lambda: accepting(port) and list(tmp_path.glob("*.can.log")), 30.0, "the recorder to listen")
        session = open_session(connect=[endpoint])
        bus = can_bus.open_bus(can_bus.resolve("udp_multicast", None, {"port": udp_port}))
        truth = session.declare_publisher(keys.truth_key(ROBOT))
        events = session.declare_publisher(keys.events_key(ROBOT))
        time.sleep(0.5)                      # the session reaches the recorder
        events.put(JUNK)
        sent = []                            # (seq, wall time)
        start = time.monotonic()
        while time.monotonic() - start < PUBLISH_BEFORE_KILL:
            seq, now = len(sent), time.time()
            truth.put(encode_message(GroundTruth(seq=seq, time=now, q=(0.01 * seq, 1.0, 0.0), qd=(0.0, 0.0, 0.0))))
            frame = cansimple.encode(cansimple.SetInputTorque(node_id=seq % 3, input_torque=0.01 * seq))
            bus.send(can.Message(arbitration_id=frame.arbitration_id, data=frame.data, dlc=frame.dlc,
                                 is_extended_id=False))
            sent.append((seq, now))
            time.sleep(0.01)
        killed_at = time.time()
        os.kill(recorder.pid, signal.SIGKILL)
        recorder.wait(timeout=10)
    finally:
        if bus is not None:
            bus.shutdown()
        if session is not None:
            session.close()
        reap([recorder])
    assert recorder.returncode == -signal.SIGKILL
    (mcap_path,) = tmp_path.glob("*.mcap")
    (log_path,) = tmp_path.glob("*.can.log")
    return mcap_path, log_path, sent, killed_at


def test_the_mcap_file_reads_up_to_within_a_second_of_the_kill(killed_recording):
    mcap_path, _, sent, killed_at = killed_recording
    messages, status = read_all(mcap_path)
    assert not status.complete and status.stopped_by       # no footer: the process never finished it
    truth = [m for m in messages if m.topic == keys.truth_key(ROBOT)]
    seqs = [m.json()["seq"] for m in truth]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))    # nothing missing in between
    last_sent_time = dict(sent)[seqs[-1]]
    assert last_sent_time > killed_at - PROMISE, (killed_at - last_sent_time, len(sent), len(seqs))
    assert truth[-1].publish_time / 1e9 == pytest.approx(last_sent_time, abs=1e-6)
    assert status.metadata["sharedctl"]["role"] == "record"
    undecoded = [m for m in messages if m.topic == UNDECODED_TOPIC]
    assert len(undecoded) == 1 and undecoded[0].json()["key"] == keys.events_key(ROBOT)


def test_the_can_log_reads_up_to_within_a_second_of_the_kill(killed_recording, tmp_path):
    _, log_path, sent, killed_at = killed_recording
    recover_can_log(log_path, tmp_path / "whole.can.log")     # drops a line cut in the middle, if any
    frames = list(can.LogReader(str(tmp_path / "whole.can.log")))
    torques = [cansimple.decode(f.arbitration_id, bytes(f.data), f.is_remote_frame, dlc=f.dlc) for f in frames]
    seqs = [round(t.input_torque / 0.01) for t in torques]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert dict(sent)[seqs[-1]] > killed_at - PROMISE
    assert frames[-1].timestamp > killed_at - PROMISE


def test_record_recover_makes_the_file_whole(killed_recording, tmp_path):
    mcap_path, _, _, _ = killed_recording
    messages, _ = read_all(mcap_path)
    result = recover_mcap(mcap_path, tmp_path / "whole.mcap")
    with open(tmp_path / "whole.mcap", "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == len(messages) == result["messages"]
        assert [m.data for _, _, m in reader.iter_messages(log_time_order=False)] == [m.data for m in messages]
