"""Frame ports (services/can_ports.py): the udp_multicast port writes python-can's datagrams byte for
byte and reads them as python-can does; an unreadable datagram is a typed error and is consumed."""
from __future__ import annotations

import time

import can
import msgpack
import pytest
from can.interfaces.udp_multicast.utils import pack_message
from hypothesis import given, settings
from hypothesis import strategies as st

from sharedctl.services.can_bus import open_bus, resolve
from sharedctl.services.can_ports import BusPort, UdpMulticastPort, UnreadableDatagram, datagram, message, port_for
from sharedctl.services.children import free_udp_port

frames = st.tuples(st.integers(0, 0x7FF), st.booleans(), st.integers(0, 8)).flatmap(
    lambda t: st.tuples(st.just(t[0]), st.just(t[1]), st.just(t[2]), st.binary(min_size=t[2], max_size=t[2])))


@settings(max_examples=300, deadline=None)
@given(frames)
def test_the_datagram_is_python_cans_byte_for_byte(frame):
    arbitration_id, remote, dlc, data = frame
    assert datagram(arbitration_id, remote, dlc, data) == pack_message(message(arbitration_id, remote, dlc, data))


def test_a_bus_without_a_multicast_socket_gets_the_generic_port():
    class Fake:
        def recv(self, timeout=None):
            return None

    assert isinstance(port_for(Fake()), BusPort) and port_for(Fake()).recv(0.0) is None


@pytest.fixture
def buses():
    spec = resolve("udp_multicast", None, udp_port=free_udp_port())
    opened = [open_bus(spec), open_bus(spec)]
    yield opened
    for bus in opened:
        bus.shutdown()


def _drain(port, seconds=0.05):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        port.recv(0.01)


@pytest.mark.processes
def test_the_udp_multicast_port_and_python_can_understand_each_other(buses):
    mine, other = buses
    port = port_for(mine)
    assert isinstance(port, UdpMulticastPort)
    sent = [(0x009, False, 8, bytes(range(8))), (0x02E, False, 4, b"\x00\x00\xc0\x3f"), (0x061, True, 8, b"")]
    for arbitration_id, remote, dlc, data in sent:
        other.send(can.Message(arbitration_id=arbitration_id, is_remote_frame=remote, dlc=dlc,
                               data=None if remote else data, is_extended_id=False))
    got = [port.recv(1.0) for _ in sent]
    assert [(f.arbitration_id, f.is_remote, f.dlc, f.data) for f in got] == sent
    assert all(not f.is_extended and not f.is_error and abs(f.arrival - time.time()) < 1.0 for f in got)
    _drain(port_for(other))
    for arbitration_id, remote, dlc, data in sent:
        port.send(arbitration_id, remote, dlc, data)
    read = [other.recv(1.0) for _ in sent]
    assert [(m.arbitration_id, m.is_remote_frame, m.dlc, bytes(m.data)) for m in read] == sent


@pytest.mark.processes
def test_recv_waits_up_to_its_timeout_and_returns_none(buses):
    port = port_for(buses[0])
    _drain(port)
    start = time.monotonic()
    assert port.recv(0.05) is None
    assert time.monotonic() - start >= 0.045
    assert port.recv(0.0) is None


@pytest.mark.processes
@pytest.mark.parametrize("raw", [
    b"\xc1",                                                   # not msgpack
    msgpack.packb(7),                                          # not a map
    msgpack.packb({"arbitration_id": 1}),                      # fields missing
    msgpack.packb({**msgpack.unpackb(datagram(9, False, 8, bytes(8))), "is_fd": True}),          # CAN FD
    msgpack.packb({**msgpack.unpackb(datagram(9, False, 8, bytes(8))), "data": 5}),              # data not bytes
    msgpack.packb({**msgpack.unpackb(datagram(9, False, 8, bytes(8))), "arbitration_id": "9"}),  # id not an int
])
def test_an_unreadable_datagram_is_a_typed_error_and_the_next_frame_is_read(buses, raw):
    mine, other = buses
    port, sender = port_for(mine), port_for(other)
    _drain(port)
    sender.sock.sendto(raw, sender.destination)
    sender.send(0x009, False, 8, bytes(8))
    with pytest.raises(UnreadableDatagram):
        port.recv(1.0)
    assert port.recv(1.0).arbitration_id == 0x009
    sender.sock.sendto(raw, sender.destination)
    sender.send(0x009, False, 8, bytes(8))
    time.sleep(0.05)
    assert [f.arbitration_id for f in port.read(10)] == [0x009] and port.bad == 1
