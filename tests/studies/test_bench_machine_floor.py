"""The machine-floor loop of `sharedctl bench` (services/bench/machine_floor.py): its bookkeeping, never its timing."""
import pytest

from sharedctl.services.studies.bench import machine_floor
from sharedctl.services.studies.bench.markdown import render

pytestmark = pytest.mark.processes      # measure() spawns a process


def test_the_floor_loop_runs_every_tick_and_counts_misses_as_the_daemon_does():
    floor = machine_floor.measure(rate_hz=500.0, seconds=0.2, work_us=50.0)
    assert floor["ticks"] == 100
    assert floor["deadline_misses"] == floor["missed"] + floor["late"]
    assert floor["work_thread_cpu_us"]["p50"] > 0.0
    assert floor["work_wall_us"]["max"] >= floor["work_wall_us"]["p50"]


def test_the_calibrated_work_grows_with_the_budget():
    assert machine_floor._calibrate(200.0) > machine_floor._calibrate(20.0)


def test_the_report_renders_the_floor_table():
    floor = machine_floor.measure(rate_hz=500.0, seconds=0.1, work_us=20.0)
    text = render({"quick": True, "machine": {}, "machine_floor": floor})
    assert "Machine floor" in text and f"| {floor['deadline_misses']} (" in text


def test_the_send_instant_splits_the_work_and_gives_a_period_jitter():
    floor = machine_floor.measure(rate_hz=500.0, seconds=0.2, work_us=60.0, pre_send_us=20.0)
    assert floor["pre_send_us"] == 20.0 and floor["work_us"] == 60.0
    # the noted instant lies inside the tick's work, so its time from the tick start never exceeds the work's
    assert floor["pre_send_wall_us"]["max"] <= floor["work_wall_us"]["max"]
    assert floor["send_jitter_us"]["p50"] >= 0.0
    whole = machine_floor.measure(rate_hz=500.0, seconds=0.1, work_us=30.0)
    assert whole["pre_send_us"] == 30.0     # by default the instant is at the end of the work


def test_on_the_bus_the_floor_sends_three_torque_frames_a_tick_at_the_output_instant():
    from sharedctl.protocol.odrive_enums import CommandId
    from sharedctl.services import can_bus, children

    port = children.free_udp_port()
    bus = can_bus.open_bus(can_bus.resolve("udp_multicast", None, {"port": port}))
    try:
        floor = machine_floor.measure(rate_hz=500.0, seconds=0.3, work_us=300.0, pre_send_us=50.0, can_port=port,
                                      hold_us=250.0)
        torque = 0
        while (msg := bus.recv(timeout=0.2)) is not None:
            torque += (msg.arbitration_id & 0x1F) == CommandId.SET_INPUT_TORQUE and msg.data[:4] == b"\0\0\0\0"
    finally:
        bus.shutdown()
    warm_up = int(machine_floor.IO_WARM_UP * 500.0)
    assert floor["on_bus"] and torque == 3 * (floor["ticks"] + warm_up)
    assert all(v > 0.0 for v in floor["io_thread_cpu_us"].values())
    # the frames leave at deadline + 250 µs, never before, though the work before them is 50 µs
    assert floor["deadline_to_send_us"]["p50"] >= 250.0 and floor["hold_us"] == 250.0


def test_a_floor_loop_that_fails_or_dies_is_reported_never_waited_for():
    with machine_floor.run(rate_hz=0.0, seconds=0.1) as loop:          # 1 / 0 inside the loop's process
        with pytest.raises(RuntimeError, match="ZeroDivisionError"):
            loop.result(60.0)
    with machine_floor.run(rate_hz=500.0, seconds=30.0) as loop:
        loop.process.kill()                                            # its own child, by its handle
        loop.process.join()
        assert loop.done()
        with pytest.raises(RuntimeError, match="sent nothing"):
            loop.result(0.5)
    assert not loop.process.is_alive()
