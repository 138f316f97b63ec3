"""CAN transports (services/can_transport/): the udp_multicast transport opens its own socket as python-can
does (hop limit 0), writes python-can's datagrams byte for byte and reads them as python-can does, so it
and real python-can buses on the same group understand each other; an unreadable datagram is a typed
error, consumed and counted; any other python-can bus goes through the generic transport."""
from __future__ import annotations

import socket
import time

import can
import msgpack
import pytest
from can.interfaces.udp_multicast.utils import pack_message
from hypothesis import given, settings
from hypothesis import strategies as st

from sharedctl.services.can_bus import open_bus, open_transport, resolve, vcan_available
from sharedctl.services.can_transport import PythonCanTransport, UnreadableFrame, transport_for
from sharedctl.services.can_transport.python_can_bus import message
from sharedctl.services.can_transport.udp_multicast import (
    SO_TIMESTAMPNS,
    UdpMulticastTransport,
    UnreadableDatagram,
    datagram,
    open_transport as open_udp_multicast,
)
from sharedctl.services.children import free_udp_port

frames = st.tuples(st.integers(0, 0x7FF) | st.integers(0x800, 0x1FFFFFFF), st.booleans(), st.integers(0, 8)).flatmap(
    lambda t: st.tuples(st.just(t[0]), st.just(t[1]), st.just(t[2]),
                        st.just(b"") if t[1] else st.binary(min_size=t[2], max_size=t[2])))


# --- the datagram, without sockets -----------------------------------------------------------------

@settings(max_examples=500, deadline=None)
@given(frames)
def test_the_datagram_is_python_cans_byte_for_byte(frame):
    arbitration_id, remote, dlc, data = frame
    expected = pack_message(can.Message(arbitration_id=arbitration_id, is_extended_id=False, is_remote_frame=remote,
                                        dlc=dlc, data=None if remote else data, check=False))
    assert datagram(arbitration_id, remote, dlc, data) == expected


def test_a_python_can_bus_is_wrapped_in_the_generic_transport_and_a_transport_is_kept():
    class Fake:
        def recv(self, timeout=None):
            return None

    wrapped = transport_for(Fake())
    assert isinstance(wrapped, PythonCanTransport) and wrapped.recv(0.0) is None
    assert transport_for(wrapped) is wrapped


def test_the_generic_transport_counts_what_python_can_cannot_read_and_reads_on():
    class Flaky:
        def __init__(self):
            self.queue = [can.CanOperationError("could not unpack received message"),
                          can.Message(arbitration_id=0x009, data=bytes(8), is_extended_id=False, timestamp=12.5)]

        def recv(self, timeout=None):
            item = self.queue.pop(0) if self.queue else None
            if isinstance(item, Exception):
                raise item
            return item

    transport = PythonCanTransport(Flaky())
    got = transport.read(10)
    assert [(f.arbitration_id, f.dlc, f.data, f.arrival) for f in got] == [(0x009, 8, bytes(8), 12.5)]
    assert transport.bad == 1


def test_udp_multicast_refuses_any_hop_limit_but_0():
    with pytest.raises(ValueError, match="hop_limit"):
        UdpMulticastTransport(port=free_udp_port(), hop_limit=1)


def test_udp_multicast_refuses_can_fd():
    with pytest.raises(ValueError, match="fd"):
        UdpMulticastTransport(port=free_udp_port(), fd=True)


def test_udp_multicast_refuses_an_option_it_does_not_know_by_name():
    with pytest.raises(ValueError, match="receive_own_messages"):
        open_udp_multicast("239.74.163.2", {"port": free_udp_port(), "receive_own_messages": True})


# --- on a real group ------------------------------------------------------------------------------

@pytest.fixture
def spec():
    return resolve("udp_multicast", None, udp_port=free_udp_port())


@pytest.fixture
def transports(spec):
    opened = [open_transport(spec), open_transport(spec)]
    yield opened
    for transport in opened:
        transport.shutdown()


@pytest.fixture
def python_can(spec):
    bus = open_bus(spec)
    yield bus
    bus.shutdown()


def _drain(transport, seconds=0.05):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        transport.recv(0.01)


SENT = [(0x009, False, 8, bytes(range(8))), (0x02E, False, 4, b"\x00\x00\xc0\x3f"), (0x061, True, 8, b"")]


@pytest.mark.processes
def test_the_socket_is_host_local_with_loopback_and_kernel_timestamps(transports):
    sock = transports[0].sock
    assert isinstance(transports[0], UdpMulticastTransport)
    assert sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 0
    assert sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP) == 1
    assert sock.getsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS) == 1


@pytest.mark.processes
def test_the_transport_reads_what_a_python_can_bus_sends_with_its_kernel_arrival_time(transports, python_can):
    # The frames go out GAP s apart and are read together afterwards: their arrival times are GAP apart
    # if they are the kernel's, microseconds apart if they were taken when read. A difference of one clock,
    # not a comparison with time.time() at chosen instants, so a stepped wall clock cannot fail it.
    transport, gap = transports[0], 0.2
    # Linux turns receive timestamping on for the whole stack lazily (a deferred static key) when the
    # first socket asks for it; a datagram queued before that carries no stamp and gets the time it is
    # read. One frame sent and read first lets that settle.
    python_can.send(can.Message(arbitration_id=0x001, data=b"", is_extended_id=False))
    assert transport.recv(1.0) is not None
    time.sleep(gap)
    for arbitration_id, remote, dlc, data in SENT:
        python_can.send(can.Message(arbitration_id=arbitration_id, is_remote_frame=remote, dlc=dlc,
                                    data=None if remote else data, is_extended_id=False))
        time.sleep(gap)
    got = [transport.recv(1.0) for _ in SENT]
    assert [(f.arbitration_id, f.is_remote, f.dlc, f.data) for f in got] == SENT
    assert all(not f.is_extended and not f.is_error for f in got)
    spacing = [b.arrival - a.arrival for a, b in zip(got, got[1:])]
    assert all(0.8 * gap <= d <= 5 * gap for d in spacing), spacing    # when it arrived, not when it was read
    assert abs(got[-1].arrival - time.time()) < 60.0                   # and on the wall clock's epoch


@pytest.mark.processes
def test_a_python_can_bus_reads_what_the_transport_sends(transports, python_can):
    for arbitration_id, remote, dlc, data in SENT:
        transports[0].send(arbitration_id, remote, dlc, data)
    read = [python_can.recv(1.0) for _ in SENT]
    assert [(m.arbitration_id, m.is_remote_frame, m.dlc, bytes(m.data)) for m in read] == SENT


@pytest.mark.processes
def test_every_transport_of_the_group_hears_every_frame_its_own_included(transports):
    transports[0].send(0x009, False, 8, bytes(8))
    assert [t.recv(1.0).arbitration_id for t in transports] == [0x009, 0x009]


@pytest.mark.processes
def test_a_forwarded_frame_is_its_datagram_unchanged(transports, python_can):
    stamped = can.Message(arbitration_id=0x009, data=bytes(8), is_extended_id=False, timestamp=1234.5, channel="x")
    python_can.send(stamped)
    first, second = transports
    frame = first.recv(1.0)
    _drain(second)
    first.forward(frame)
    assert second.recv(1.0).raw == pack_message(stamped)


@pytest.mark.processes
def test_the_generic_transport_and_the_udp_multicast_transport_understand_each_other(transports, python_can):
    generic = PythonCanTransport(python_can)
    for arbitration_id, remote, dlc, data in SENT:
        generic.send(arbitration_id, remote, dlc, data)
    got = [transports[0].recv(1.0) for _ in SENT]
    assert [(f.arbitration_id, f.is_remote, f.dlc, f.data) for f in got] == SENT
    _drain(generic)
    transports[0].send(*SENT[0])
    assert [generic.recv(1.0)[:6]] == [(0x009, False, False, False, 8, bytes(range(8)))]


@pytest.mark.processes
def test_recv_waits_up_to_its_timeout_and_returns_none(transports):
    transport = transports[0]
    _drain(transport)
    start = time.monotonic()
    assert transport.recv(0.05) is None
    assert time.monotonic() - start >= 0.045
    assert transport.recv(0.0) is None


@pytest.mark.processes
@pytest.mark.parametrize("raw", [
    b"\xc1",                                                   # not msgpack
    msgpack.packb(7),                                          # not a map
    msgpack.packb({"arbitration_id": 1}),                      # fields missing
    msgpack.packb({**msgpack.unpackb(datagram(9, False, 8, bytes(8))), "is_fd": True}),          # CAN FD
    msgpack.packb({**msgpack.unpackb(datagram(9, False, 8, bytes(8))), "data": 5}),              # data not bytes
    msgpack.packb({**msgpack.unpackb(datagram(9, False, 8, bytes(8))), "arbitration_id": "9"}),  # id not an int
])
def test_an_unreadable_datagram_is_a_typed_error_and_the_next_frame_is_read(transports, raw):
    mine, sender = transports
    _drain(mine)
    sender.sock.sendto(raw, sender.destination)
    sender.send(0x009, False, 8, bytes(8))
    with pytest.raises(UnreadableDatagram) as caught:
        mine.recv(1.0)
    assert isinstance(caught.value, UnreadableFrame)
    assert mine.recv(1.0).arbitration_id == 0x009
    sender.sock.sendto(raw, sender.destination)
    sender.send(0x009, False, 8, bytes(8))
    time.sleep(0.05)
    assert [f.arbitration_id for f in mine.read(10)] == [0x009] and mine.bad == 1


def test_an_interface_without_a_plug_in_opens_as_a_python_can_bus_in_the_generic_transport():
    spec = resolve("virtual", "sharedctl-transport-test")        # python-can's in-process bus
    with open_transport(spec) as sender, open_transport(spec) as receiver:
        assert isinstance(sender, PythonCanTransport)
        sender.send(*SENT[2])
        sender.send(*SENT[0])
        frames = [receiver.recv(1.0) for _ in range(2)]
    assert [(f.arbitration_id, f.is_remote, f.dlc, f.data) for f in frames] == [SENT[2], SENT[0]]


@pytest.mark.processes
@pytest.mark.skipif(not vcan_available("vcan0"),
                    reason="needs SocketCAN vcan0 (deploy/vcan-setup.sh); this kernel has no vcan")
def test_socketcan_opens_as_the_generic_transport_and_carries_frames():
    spec = resolve("socketcan", "vcan0")
    with open_transport(spec) as sender, open_transport(spec) as receiver:
        assert isinstance(sender, PythonCanTransport)
        _drain(receiver)
        sender.send(*SENT[0])
        frame = receiver.recv(1.0)
    assert (frame.arbitration_id, frame.is_remote, frame.dlc, frame.data) == SENT[0]


def test_the_generic_message_is_a_classic_standard_id_frame():
    msg = message(0x061, True, 8, b"")
    fields = (msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.dlc, bytes(msg.data))
    assert fields == (0x061, False, True, 8, b"")
