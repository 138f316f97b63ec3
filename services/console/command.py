"""`sharedctl console [--script SCENARIO] [--headless] [--duration S] [--zenoh-connect EP | --zenoh-listen EP]
[--robot-id ID] [--operator-id NAME] [--signing-key FILE] [--scenario FILE] [--input keyboard|gamepad
[--device PATH] [--gamepad-profile FILE]]` — the operator console (docs/console.md)."""
from __future__ import annotations

import sys
import time

from sharedctl.protocol.errors import KeyExprError
from sharedctl.scenario import ScenarioError

from ..lifecycle import StopFlag
from ..service_config import add_argument as add_service_config_argument
from ..scenario_files import load
from ..security import zenoh_config
from ..security.signing import Signer, SigningError
from ..zenoh_session import DEFAULT_ENDPOINT, EndpointError
from .gamepad import Gamepad, GamepadError
from .gamepad_profile import load_profile


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("console",
                              help="operator console: live dashboard, keyboard joystick or scripted operator")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--script", metavar="SCENARIO",
                       help="the scenario's scripted operator drives (file or packaged name)")
    which.add_argument("--scenario", metavar="FILE",
                       help="scenario for the map and initial pose in keyboard mode (default paper_convex)")
    p.add_argument("--headless", action="store_true", help="no dashboard, no keyboard; print one line at the end")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds (default: until SIGINT/SIGTERM)")
    link = p.add_mutually_exclusive_group()
    link.add_argument("--zenoh-connect", metavar="EP", action="append",
                      help=f"connect to a loopback endpoint (repeatable; default {DEFAULT_ENDPOINT})")
    link.add_argument("--zenoh-listen", metavar="EP", help="listen on a loopback endpoint instead")
    zenoh_config.add_argument(p)
    p.add_argument("--robot-id", default="robot1", help="robot id in the key expressions (default robot1)")
    p.add_argument("--operator-id", default="operator", help="operator id sent with every command")
    p.add_argument("--signing-key", metavar="FILE",
                   help="the operator's Ed25519 key (NAME.signing-key.pem from `sharedctl credentials`): every command "
                        "and lease request is signed as --operator-id, which a controller with --operators requires")
    p.add_argument("--rate", type=float, default=50.0, metavar="HZ", help="command rate (default 50)")
    p.add_argument("--deadman", choices=("hold", "toggle"), default="hold",
                   help="the deadman holds while space repeats (default), or space toggles it: toggle latches, "
                        "so it is not a deadman (unsafe)")
    p.add_argument("--input", choices=("keyboard", "gamepad"), default="keyboard",
                   help="who drives without --script: the keyboard's virtual joystick (default) or a gamepad "
                        "(evdev, Linux; the 'gamepad' extra)")
    p.add_argument("--device", metavar="PATH",
                   help="the gamepad's event device, e.g. /dev/input/event5 (default: the first joystick that fits "
                        "the profile)")
    p.add_argument("--gamepad-profile", metavar="FILE",
                   help="the gamepad's axes, scales and buttons (TOML, teleop_twist_joy's keys; default: the packaged "
                        "Xbox-style profile)")
    add_service_config_argument(p)
    p.set_defaults(handler=run)


def run(args) -> int:
    from .app import ConsoleApp, ConsoleOptions

    stop = StopFlag().install()
    try:
        scenario = load(args.scenario or args.script or "paper_convex")
        signer = Signer.from_file(args.signing_key, args.operator_id) if args.signing_key else None
    except (ScenarioError, SigningError) as exc:
        print(f"sharedctl console: {exc}", file=sys.stderr)
        return 2
    if args.rate <= 0 or (args.duration is not None and args.duration <= 0):
        print("sharedctl console: --rate and --duration must be positive", file=sys.stderr)
        return 2
    gamepad = None
    if args.input == "gamepad" or args.device or args.gamepad_profile:
        try:
            gamepad = open_gamepad(args)
        except (ValueError, GamepadError) as exc:      # ProfileError is a ValueError
            print(f"sharedctl console: {exc}", file=sys.stderr)
            return 2
    interactive = not args.headless and sys.stdin.isatty() and sys.stdout.isatty()
    options = ConsoleOptions(
        scenario=scenario, script=args.script is not None, headless=not interactive, duration=args.duration,
        listen=[args.zenoh_listen] if args.zenoh_listen else None,
        connect=None if args.zenoh_listen or (args.zenoh_config and not args.zenoh_connect)
        else (args.zenoh_connect or [DEFAULT_ENDPOINT]), zenoh_config=args.zenoh_config,
        robot_id=args.robot_id, operator_id=args.operator_id, rate=args.rate, deadman_mode=args.deadman,
        signer=signer, gamepad=gamepad,
    )
    try:
        zenoh_config.check_session_args(options.zenoh_config, options.listen, options.connect)
        return ConsoleApp(options).run(stop, interactive)
    except (EndpointError, KeyExprError, zenoh_config.ZenohConfigError) as exc:
        print(f"sharedctl console: {exc}", file=sys.stderr)
        return 2


def open_gamepad(args):
    """The gamepad reader, its device open (imports evdev: the `gamepad` extra). ValueError, GamepadError: why not."""
    if args.input != "gamepad":
        raise ValueError("--device and --gamepad-profile need --input gamepad")
    if args.script:
        raise ValueError("--input gamepad drives in place of the keyboard; --script drives by itself")
    from .gamepad_device import EvdevBackend, GamepadReader

    reader = GamepadReader(Gamepad(load_profile(args.gamepad_profile)), EvdevBackend(), args.device)
    reader.open(time.monotonic())
    return reader
