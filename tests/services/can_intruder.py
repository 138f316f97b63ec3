"""Another CAN master: sends Set_Input_Torque frames, encoded with cantools from the CANSimple DBC, onto a
host-local udp_multicast bus — what tests/services/test_foreign_can_master.py points at a running demo.

    python tests/services/can_intruder.py PORT NODE TORQUE RATE_HZ SECONDS

Prints the wall time of its first frame. Nothing from sharedctl's own codec: the DBC and python-can only.
"""
import sys
import time

import can
import cantools

from sharedctl.protocol.dbc import DBC_PATH


def main(port: int, node: int, torque: float, rate: float, seconds: float) -> None:
    db = cantools.database.load_file(str(DBC_PATH))
    message = db.get_message_by_name(f"Axis{node}_Set_Input_Torque")
    data = message.encode({"Input_Torque": torque})
    with can.Bus(interface="udp_multicast", channel="239.74.163.2", port=port, hop_limit=0) as bus:
        frame = can.Message(arbitration_id=message.frame_id, data=data, is_extended_id=False)
        end, first = time.monotonic() + seconds, None
        while time.monotonic() < end:
            bus.send(frame)
            first = first or time.time()
            time.sleep(1.0 / rate)
    print(first, flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5]))
