"""Opening sessions (services/zenoh_session.py): a peer started before the one it connects to is
connected soon after that one listens — the console is started before its controller."""
import json
import threading
import time

import pytest

from sharedctl.services import zenoh_session

pytestmark = pytest.mark.processes


def test_a_peer_started_before_its_listener_is_connected_within_a_fraction_of_a_second():
    port = zenoh_session.free_loopback_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    early = zenoh_session.open_session(connect=[endpoint])          # nobody listens yet: retried
    heard = threading.Event()
    listener = None
    try:
        time.sleep(1.2)
        listener = zenoh_session.open_session(listen=[endpoint])
        listening_at = time.monotonic()
        sub = listener.declare_subscriber("sharedctl/test/early", lambda _sample: heard.set())
        pub = early.declare_publisher("sharedctl/test/early")
        while not heard.is_set() and time.monotonic() - listening_at < 5.0:
            pub.put(b"x")
            time.sleep(0.01)
        connected_after = time.monotonic() - listening_at
        sub.undeclare()
        pub.undeclare()
    finally:
        early.close()
        if listener is not None:
            listener.close()
    assert heard.is_set()
    # Zenoh's own retry (1 s, doubling up to 4 s) waits until about 3 s after the first attempt here,
    # 1.3 s after the listener appears; ours tries every 250 ms at most
    assert connected_after < 0.6, connected_after


def test_the_configuration_keeps_scouting_off_and_retries_quickly():
    cfg = zenoh_session.config(connect=["tcp/127.0.0.1:7447"])
    assert cfg.get_json("scouting/multicast/enabled") == "false"
    retry = json.loads(cfg.get_json("connect/retry"))
    assert retry["period_init_ms"] <= 100 and retry["period_max_ms"] <= 1000
    with pytest.raises(zenoh_session.EndpointError):
        zenoh_session.config(connect=["tcp/10.0.0.1:7447"])
