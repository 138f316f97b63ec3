"""The far end of the bare transport hops: a process that only sends timestamps.

    python -m sharedctl.services.studies.bench.hop_probe zenoh ENDPOINT SECONDS RATE_HZ
    python -m sharedctl.services.studies.bench.hop_probe can UDP_PORT SECONDS RATE_HZ

`zenoh`: connects to ENDPOINT (loopback) and puts 8-byte wall-clock send times on PROBE_KEY;
`can`: sends one 8-byte frame (id PROBE_CAN_ID) carrying the send time on the host-local
udp_multicast bus at UDP_PORT. The bench (same host, same clock) records the arrival times.
No control math, no decoding: what is left is the transport's own cost, the floor under the
sensor → torque and operator → torque latencies measured in the same run.
"""
from __future__ import annotations

import struct
import sys
import time

PROBE_KEY = "sharedctl/v1/bench/probe"
PROBE_CAN_ID = 0x7F0       # node 63, command 0x10: no wheel's node, so no drive or master decodes it


def pack_time(t: float) -> bytes:
    return struct.pack("<d", t)


def unpack_time(data: bytes) -> float:
    return struct.unpack("<d", bytes(data[:8]))[0]


def _paced(seconds: float, rate: float, send) -> int:
    from sharedctl.services.lifecycle import RateClock, StopFlag

    stop = StopFlag().install()
    clock = RateClock(1.0 / rate)
    end = time.monotonic() + seconds
    sent = 0
    while not stop.stopped and time.monotonic() < end:
        clock.wait()
        send()
        sent += 1
    return sent


def run_zenoh(endpoint: str, seconds: float, rate: float) -> int:
    from sharedctl.services.zenoh_session import open_session

    session = open_session([], [endpoint])
    try:
        publisher = session.declare_publisher(PROBE_KEY)
        time.sleep(0.3)     # let the subscription propagate before the first put
        sent = _paced(seconds, rate, lambda: publisher.put(pack_time(time.time())))
        publisher.undeclare()
        return sent
    finally:
        session.close()


def run_can(port: int, seconds: float, rate: float) -> int:
    import can

    from sharedctl.services.can_bus import open_bus, resolve

    bus = open_bus(resolve("udp_multicast", None, {"port": port}))
    try:
        def send():
            bus.send(can.Message(arbitration_id=PROBE_CAN_ID, data=pack_time(time.time()), is_extended_id=False))
        return _paced(seconds, rate, send)
    finally:
        bus.shutdown()


def main(argv: list[str]) -> int:
    if len(argv) != 4 or argv[0] not in ("zenoh", "can"):
        print(__doc__, file=sys.stderr)
        return 2
    kind, where, seconds, rate = argv[0], argv[1], float(argv[2]), float(argv[3])
    sent = run_zenoh(where, seconds, rate) if kind == "zenoh" else run_can(int(where), seconds, rate)
    print(f"hop_probe {kind}: sent {sent}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
