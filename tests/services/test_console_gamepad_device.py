"""The gamepad's evdev shell (services/console/gamepad_device.py) on recorded devices, and its wiring into the
console: the pad's commands go through the keyboard's sender (same counter, same publisher, same signing)."""
import os
import threading
import time

import pytest

from sharedctl.protocol.messages import Authority, LinkHealth, OperatorCommand, RobotState, SetClass
from sharedctl.protocol.msgpack_codec import decode_message
from sharedctl.protocol.wire_types import ROBOT_DIMS
from sharedctl.services import cli
from sharedctl.services.console.app import ConsoleApp, ConsoleOptions
from sharedctl.services.console.gamepad import AbsInfo, DeviceInfo, Gamepad, GamepadError
from sharedctl.services.console.gamepad_device import GamepadReader
from sharedctl.services.console.gamepad_profile import load_profile
from sharedctl.services.lifecycle import StopFlag
from sharedctl.services.scenario_files import load

evdev = pytest.importorskip("evdev")
from .gamepad_recording import Recording, RecordedBackend, RecordedDevice  # noqa: E402 — needs evdev: after the skip

XBOX = load_profile()
E = evdev.ecodes


def recorded(name: str, path: str | None = None) -> RecordedDevice:
    return RecordedDevice(Recording.load(name), path)


def other(path: str, name: str, absinfo: dict, keys: set) -> RecordedDevice:
    """A device that is not the pad (header only)."""
    return RecordedDevice(Recording(DeviceInfo(path, name, "usb-0000:00:14.0-1/input3",
                                               {c: AbsInfo(0, *r) for c, r in absinfo.items()}, frozenset(keys)),
                                    frozenset(), []))


TOUCHPAD = other("/dev/input/event4", "Sony Interactive Entertainment DualSense Wireless Controller Touchpad",
                 {E.ABS_X: (0, 1919), E.ABS_Y: (0, 1079), E.ABS_MT_POSITION_X: (0, 1919)},
                 {E.BTN_LEFT, E.BTN_TOUCH, E.BTN_TOOL_FINGER})
MOTION = other("/dev/input/event5", "Sony Interactive Entertainment DualSense Wireless Controller Motion Sensors",
               {E.ABS_X: (-32768, 32767), E.ABS_Y: (-32768, 32767), E.ABS_Z: (-32768, 32767)}, set())


def pump_all(reader: GamepadReader, device: RecordedDevice, now: float) -> list[str]:
    actions = []
    while not device.done and reader.device is not None:
        actions += reader.pump(now)
    return actions


# ----- finding the device ---------------------------------------------------
def test_without_device_the_first_joystick_that_fits_the_profile_is_opened():
    pad = recorded("xbox360_drive.jsonl")          # /dev/input/event17, after a touchpad and motion sensors
    reader = GamepadReader(Gamepad(XBOX), RecordedBackend(TOUCHPAD, MOTION, pad))
    info = reader.open(0.0)
    assert info.name == "Microsoft X-Box 360 pad" and reader.device is pad
    assert TOUCHPAD.closed and MOTION.closed and reader.backend.opened == [TOUCHPAD.path, MOTION.path, pad.path]


def test_no_readable_device_says_the_user_must_be_in_group_input():
    backend = RecordedBackend(recorded("xbox360_drive.jsonl"), unreadable=("/dev/input/event17",))
    with pytest.raises(GamepadError, match=r"no gamepad found: no readable .*group 'input'"):
        GamepadReader(Gamepad(XBOX), backend).open(0.0)


def test_no_joystick_among_the_devices_is_a_clear_error():
    with pytest.raises(GamepadError, match=r"none of the 2 readable input devices has joystick axes"):
        GamepadReader(Gamepad(XBOX), RecordedBackend(TOUCHPAD, MOTION)).open(0.0)


def test_a_joystick_without_a_bound_button_is_refused_naming_the_key():
    stick = other("/dev/input/event6", "Thrustmaster T.16000M", {E.ABS_X: (0, 16383), E.ABS_Y: (0, 16383),
                                                                  E.ABS_RZ: (0, 255)}, {E.BTN_TRIGGER, E.BTN_THUMB})
    with pytest.raises(GamepadError, match=r"axis_angular.yaw: 'Thrustmaster T.16000M'"):
        GamepadReader(Gamepad(XBOX), RecordedBackend(stick)).open(0.0)


def test_a_device_path_that_is_missing_or_unreadable_is_a_clear_error():
    backend = RecordedBackend(recorded("xbox360_drive.jsonl"), unreadable=("/dev/input/event17",))
    with pytest.raises(GamepadError, match=r"/dev/input/event9: no such device"):
        GamepadReader(Gamepad(XBOX), backend, "/dev/input/event9").open(0.0)
    with pytest.raises(GamepadError, match=r"/dev/input/event17: permission denied: .*group 'input'"):
        GamepadReader(Gamepad(XBOX), backend, "/dev/input/event17").open(0.0)


# ----- reading ----------------------------------------------------------------
def test_the_reader_feeds_frames_and_answers_syn_dropped_with_the_devices_state():
    device = recorded("xbox360_syn_dropped.jsonl")
    reader = GamepadReader(Gamepad(XBOX), RecordedBackend(device), device.path)
    reader.open(0.0)
    actions = pump_all(reader, device, 0.1)
    pad = reader.pad
    assert actions.count("stop") == 1 and pad.counters.resyncs == 1
    # the last frame presses LB again; ABS_Y read back by ioctl: −20000 → y = 0.2882313 (test_console_gamepad.py)
    assert pad.deadman(0.1) and pad.deflection(0.1) == pytest.approx([0.0, 0.2882313, 0.0], abs=1e-6)


def test_an_unplugged_pad_is_hands_off_and_the_same_pad_is_opened_again_when_it_comes_back():
    first = recorded("xbox360_unplug.jsonl")
    backend = RecordedBackend(first)
    reader = GamepadReader(Gamepad(XBOX), backend, reopen_period=0.5)
    reader.open(0.0)
    pad = reader.pad
    actions = pump_all(reader, first, 0.1)
    assert pad.deadman(0.1) is False and reader.device is None and first.closed
    assert actions[-1] == "stop" and pad.status == "gamepad disconnected"
    assert reader.last_error == "No such device"
    del backend.devices[first.path]
    backend.devices["/dev/input/event18"] = other("/dev/input/event18", "Logitech Gamepad F310",
                                                  {E.ABS_X: (-32768, 32767), E.ABS_Y: (-32768, 32767),
                                                   E.ABS_RX: (-32768, 32767)}, set(XBOX.buttons().values()))
    assert reader.pump(1.0) == [] and reader.device is None               # another pad is not this one
    again = recorded("xbox360_replug.jsonl")                              # same name and phys, event19
    backend.devices[again.path] = again
    reader.pump(1.2)
    assert reader.device is None                                          # not yet: looks every 0.5 s
    reader.pump(1.6)
    assert reader.device is again and pad.status is None and pad.counters.connects == 2
    assert not pad.deadman(1.6)                                           # LB held since it came back
    pump_all(reader, again, 1.7)
    assert pad.deadman(1.7) and pad.deflection(1.7) == pytest.approx([0.0, 0.3879125, 0.0], abs=1e-6)


def test_a_device_file_that_vanishes_without_a_read_error_is_a_disconnect():
    device = recorded("xbox360_drive.jsonl")
    backend = RecordedBackend(device)
    reader = GamepadReader(Gamepad(XBOX), backend, reopen_period=0.5)
    reader.open(0.0)
    del backend.devices[device.path]
    assert reader.pump(0.2) == [] and reader.device is not None           # checked every 0.5 s
    assert reader.pump(0.6) == ["stop"] and reader.pad.status == "gamepad disconnected"


def test_the_reader_thread_survives_an_unplug_and_reports_it():
    device = recorded("xbox360_unplug.jsonl")
    reader = GamepadReader(Gamepad(XBOX), RecordedBackend(device), reopen_period=0.05)
    reader.open(time.monotonic())
    reader.wait = lambda timeout, stop: stop.wait(0.005)                  # a recorded device has no fd to select on
    stop, seen = StopFlag(), []
    thread = threading.Thread(target=reader.run, args=(stop, threading.Lock(), seen.extend), daemon=True)
    thread.start()
    deadline = time.monotonic() + 5.0
    while reader.pad.status is None and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.1)                                                       # it keeps looking for the pad
    alive = thread.is_alive()
    stop.stop()
    thread.join(2.0)
    assert alive and reader.pad.status == "gamepad disconnected" and seen[-1] == "stop"


@pytest.mark.skipif(not os.access("/dev/uinput", os.W_OK), reason="this kernel has no uinput")
def test_a_virtual_xbox_pad_drives_and_its_removal_is_a_disconnect():
    from evdev import AbsInfo as EvAbs
    from evdev import UInput

    from sharedctl.services.console.gamepad_device import EvdevBackend

    stick = EvAbs(0, -32768, 32767, 16, 128, 0)
    caps = {E.EV_KEY: sorted(set(XBOX.buttons().values())),
            E.EV_ABS: [(E.ABS_X, stick), (E.ABS_Y, stick), (E.ABS_RX, stick), (E.ABS_RY, stick)]}
    ui = UInput(caps, name="Microsoft X-Box 360 pad")
    try:
        time.sleep(0.3)                                                    # udev makes the node
        reader = GamepadReader(Gamepad(XBOX), EvdevBackend(), ui.device.path)
        reader.open(time.monotonic())
        for code, value in ((E.BTN_TL, 1), (E.ABS_Y, -32768)):
            ui.write(E.EV_KEY if code == E.BTN_TL else E.EV_ABS, code, value)
            ui.syn()
        time.sleep(0.05)
        reader.pump(time.monotonic())
        assert reader.pad.deadman(0.0) and reader.pad.deflection(0.0) == pytest.approx([0.0, 0.5, 0.0])
    finally:
        ui.close()
    time.sleep(0.1)
    assert reader.pump(time.monotonic() + 1.0) and reader.pad.status == "gamepad disconnected"


# ----- the command line ------------------------------------------------------
def test_a_missing_device_or_a_gamepad_with_a_script_stops_the_console_with_exit_2(capsys):
    assert cli.main(["console", "--input", "gamepad", "--device", "/dev/input/event-none", "--headless"]) == 2
    assert "/dev/input/event-none: no such device" in capsys.readouterr().err
    assert cli.main(["console", "--script", "paper_convex", "--input", "gamepad"]) == 2
    assert "--script drives by itself" in capsys.readouterr().err


# ----- the console's wiring --------------------------------------------------
def robot_state() -> RobotState:
    z = (0.0, 0.0, 0.0)
    return RobotState(seq=1, time=1.0, q=(-0.9, 3.0, 0.0), qd_hat=z, q_ref=(-0.9, 3.0, 0.0),
                      group_classes=(SetClass.SAFE,), active_group=0, authority=Authority.HUMAN, k_s=1.0, k_h=1.0,
                      k_f=0.0, u_h=z, u_f=z, u_s=z, wheel_torques=z, theta_hat=z, min_margin=0.5,
                      region_margins=(0.5,), estop_active=False, lease_holder="operator",
                      link=LinkHealth(operator_latency_ms=0.0, loss_fraction=0.0, staleness_ms=0.0,
                                      can_feedback_age_ms=0.0))


class Publisher:
    key_expr = "sharedctl/v1/robot1/operator/cmd"

    def __init__(self) -> None:
        self.sent: list[tuple[float, OperatorCommand]] = []

    def put(self, payload, attachment=None) -> None:
        self.sent.append((time.monotonic(), decode_message(payload, ROBOT_DIMS, expect=OperatorCommand)))


def console(name: str, rate: float = 50.0):
    """A console in gamepad mode on a recorded pad, holding control, its UI alive and telemetry fresh."""
    device = recorded(name)
    reader = GamepadReader(Gamepad(XBOX), RecordedBackend(device), device.path)
    reader.open(time.monotonic())
    app = ConsoleApp(ConsoleOptions(scenario=load("paper_convex"), gamepad=reader, rate=rate))
    app.lease.holding = True
    app.telemetry.state, app.telemetry.state_arrival = robot_state(), time.monotonic() + 3600.0
    app.ui_alive_at = time.monotonic() + 3600.0
    return app, reader, device


def pump_until(app, reader, device, code: int, value: int) -> list[str]:
    """Pump frames until one holding (code, value) has been read; the actions of that frame."""
    while not device.done:
        at = device._at
        actions = reader.pump(time.monotonic())
        read = device.rec.lines[at:device._at]
        if any(not isinstance(e, tuple) and (e.code, e.value) == (code, value) for e in read):
            return actions
    raise AssertionError("not in the recording")


def test_the_pads_commands_go_out_with_the_keyboards_counter_and_session():
    app, reader, device = console("xbox360_drive.jsonl")
    pump_until(app, reader, device, E.ABS_Y, -32768)
    cmd = app.next_command(time.monotonic())
    assert app.mode == "gamepad" and cmd.deadman and cmd.joystick == pytest.approx((0.5, 0.5, 0.0))
    assert cmd.q_d == pytest.approx((-0.9 + 0.25, 3.0 + 0.25, 0.0))
    assert cmd.session_id == app.keyboard.counter.session_id and app.keyboard.counter.seq == cmd.seq == 1


def test_an_unplugged_pad_sends_hands_off_and_says_so_while_an_estop_still_goes_out():
    app, reader, device = console("xbox360_unplug.jsonl")
    pump_all(reader, device, time.monotonic())
    cmd = app.next_command(time.monotonic())
    assert not cmd.deadman and not any(cmd.joystick) and cmd.q_d == (-0.9, 3.0, 0.0)
    assert app.blind == "gamepad disconnected"
    assert "HANDS-OFF: gamepad disconnected" in app.view(None, None).control
    app.on_keys(["x"], time.monotonic())
    assert app.next_command(time.monotonic()).estop


def test_in_gamepad_mode_the_terminal_does_not_drive_but_estops_and_clears_the_pads_estop():
    app, reader, device = console("xbox360_buttons.jsonl")
    app.on_keys(["space", "up", "right"], time.monotonic())
    assert not app.next_command(time.monotonic()).deadman and not any(app.next_command(time.monotonic()).joystick)
    app.on_gamepad(pump_until(app, reader, device, E.BTN_B, 1))
    assert app.next_command(time.monotonic()).estop and app.urgent.is_set()
    app.on_keys(["c"], time.monotonic())
    assert not app.next_command(time.monotonic()).estop


def test_the_pads_take_and_release_buttons_ask_the_lease_client():
    app, reader, device = console("xbox360_buttons.jsonl")
    app.lease.want(False)
    app.on_gamepad(pump_until(app, reader, device, E.BTN_START, 1))
    assert app.lease.wants
    app.on_gamepad(pump_until(app, reader, device, E.BTN_SELECT, 1))
    assert not app.lease.wants


def test_letting_go_of_the_enable_button_is_sent_at_once_not_at_the_next_tick():
    app, reader, device = console("xbox360_drive.jsonl", rate=1.0)     # a tick every second
    pump_until(app, reader, device, E.ABS_Y, -32768)
    publisher, stop = Publisher(), StopFlag()
    sender = threading.Thread(target=app.sender, args=(publisher, stop), daemon=True)
    sender.start()
    try:
        deadline = time.monotonic() + 2.0
        while not publisher.sent and time.monotonic() < deadline:
            time.sleep(0.005)
        assert publisher.sent[0][1].deadman                                  # the tick at start: driving
        with app.lock:
            actions = pump_until(app, reader, device, E.BTN_TL, 0)
        released = time.monotonic()
        app.on_gamepad(actions)
        while len(publisher.sent) < 2 and time.monotonic() < released + 0.5:
            time.sleep(0.002)
    finally:
        stop.stop()
        app.urgent.set()
        sender.join(2.0)
    arrival, cmd = publisher.sent[1]
    assert not cmd.deadman and not any(cmd.joystick)
    assert arrival - released < 0.25                                          # the next tick was ~1 s away
