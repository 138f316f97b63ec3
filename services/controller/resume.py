"""How a controller starts: from which pose, and whether it may arm the drives.

A controller arms only drives it has disarmed itself in this life (the daemon sends IDLE to every
axis first and waits to hear each one idle: `Mode.STARTING`). Then `decide` picks one of three
starts from what it can trust:

* **declared pose** (`--pose scenario`): whoever started the controller says the robot stands at
  the scenario's start pose (a first start, a re-homing). It arms at once — unless a drive
  reports an Estop, which stays latched until an operator takes control.
* **resumed** (`--pose checkpoint`, the default, with the checkpoint of a controller that did not
  end on purpose): the pose is the checkpoint's, carried forward by the odometry over the wheel
  encoder increments since it was written. The drives stay disarmed until an operator takes control
  (in-band take); a latched Estop stays latched. Trusted only if the checkpoint is this robot's and
  scenario's, whole, younger than `max_age`, and the encoders moved no more since than the wheels
  can turn in that time (`max_wheel_speed`) — otherwise the drives may have restarted and their
  readings no longer continue the checkpoint's. The drives witness that too: a controller that
  dies with them armed leaves every one of them with an error (their watchdog expires), and an
  Estop stays on them; armed or estopped in the checkpoint and without an error now, they were
  restarted (power cycled, replaced, a new simulation) and their encoders count from a new origin.
* **first life** (`--pose checkpoint` with no checkpoint, or the last one ended on purpose): the
  scenario's start pose — provided no drive reports an error at start. An error (a watchdog that
  expired, an Estop) says a controller was driving them, and with no checkpoint of it the pose is
  unknown.

Whatever cannot be trusted is a refusal: the controller stays disarmed, says why (an Event, the
start line, the summary) and arms nothing until it is restarted with an honest pose.

Pure: what the checkpoint and the drives say in, a `Start` out.
"""
from __future__ import annotations

from dataclasses import dataclass

from sharedctl.protocol.odrive_enums import ODriveError

from .checkpoint import Checkpoint, CheckpointError

POSE_SOURCES = ("checkpoint", "scenario")
DEFAULT_MAX_AGE = 60.0          # s: an older checkpoint is not resumed from
DEFAULT_MAX_WHEEL_SPEED = 15.0  # turns/s a wheel cannot exceed (≈ 3.7 m/s on the omni robot's 39.65 mm wheels)
TURNS_SLACK = 0.25              # turns of encoder change allowed beyond max_wheel_speed × age


@dataclass(frozen=True)
class Start:
    action: str                 # "arm" | "hold" (disarmed until an operator takes) | "estop" (latched) | "refuse"
    q: tuple                    # the pose at `wheel_turns`
    wheel_turns: tuple          # encoder readings `q` belongs to (the odometry integrates on from there)
    theta_hat: tuple | None     # the adaptive estimate to start from (None: the scenario's)
    text: str                   # what was decided and why, for the start line and an Event


def decide(pose_source: str, checkpoint: Checkpoint | CheckpointError | None, *, robot_id: str, scenario: str,
           q0, turns, errors, age: float | None = None, max_age: float = DEFAULT_MAX_AGE,
           max_wheel_speed: float = DEFAULT_MAX_WHEEL_SPEED) -> Start:
    """The start. `turns`: the wheels' encoder readings now; `errors`: each drive's active errors now (node
    order); `age`: the checkpoint's age (s, `Checkpoint.age`)."""
    q0, turns = tuple(float(x) for x in q0), tuple(float(x) for x in turns)
    faulted = {i: ODriveError(e) for i, e in enumerate(errors) if ODriveError(e) != ODriveError.NONE}
    estopped = [i for i, e in faulted.items() if e & ODriveError.ESTOP_REQUESTED]
    if pose_source == "scenario":
        if estopped:
            return Start("estop", q0, turns, None, f"pose declared at the scenario's start; drives {estopped} report "
                                                   "an Estop: latched until an operator takes control")
        return Start("arm", q0, turns, None, "pose declared at the scenario's start")
    if pose_source != "checkpoint":
        raise ValueError(f"pose source must be one of {POSE_SOURCES}, got {pose_source!r}")
    if isinstance(checkpoint, CheckpointError):
        return _refuse(q0, turns, f"the checkpoint cannot be used: {checkpoint}")
    if checkpoint is None or checkpoint.ended:
        if faulted:
            names = ", ".join(f"axis {i}: {e.name or hex(int(e))}" for i, e in faulted.items())
            previous = "the last controller ended on purpose" if checkpoint is not None else "there is no checkpoint"
            return _refuse(q0, turns, f"{previous}, yet the drives report errors at start ({names}): a controller "
                                      "was driving them and where it left the robot is unknown")
        return Start("arm", q0, turns, None,
                     "first start: the scenario's start pose" if checkpoint is None
                     else "the last controller ended on purpose: a first start at the scenario's start pose")
    if checkpoint.robot_id != robot_id or checkpoint.scenario != scenario:
        return _refuse(q0, turns, f"the checkpoint is of robot {checkpoint.robot_id!r}, scenario "
                                  f"{checkpoint.scenario!r}, not {robot_id!r}, {scenario!r}")
    if len(checkpoint.wheel_turns) != len(turns) or len(checkpoint.q) != len(q0):
        return _refuse(q0, turns, "the checkpoint is of another robot shape")
    if age is None or not age <= max_age:
        return _refuse(q0, turns, f"the checkpoint is {age:.1f} s old (at most {max_age:g} s): the robot may have "
                                  "been moved or its drives restarted since")
    if (checkpoint.armed or checkpoint.estop) and len(faulted) < len(turns):
        clean = sorted(set(range(len(turns))) - set(faulted))
        was = "estopped" if checkpoint.estop else "armed"
        return _refuse(q0, turns, f"the drives were {was} when the checkpoint was written, yet drives {clean} report "
                                  "no error now (a controller that dies leaves their watchdog expired, an Estop "
                                  "stays on them): they restarted since, and their encoders no longer continue "
                                  "the checkpoint's")
    limit = max_wheel_speed * age + TURNS_SLACK
    for i, (now, then) in enumerate(zip(turns, checkpoint.wheel_turns)):
        if abs(now - then) > limit:
            return _refuse(q0, turns, f"wheel {i} reads {now - then:+.2f} turns since the checkpoint {age:.1f} s ago, "
                                      f"more than it can turn ({limit:.2f}): its drive restarted or is another")
    text = f"resumed from a checkpoint {age:.2f} s old: disarmed until an operator takes control"
    if checkpoint.estop or estopped:
        why = checkpoint.reason if checkpoint.estop else f"drives {estopped} report an Estop"
        return Start("estop", checkpoint.q, checkpoint.wheel_turns, checkpoint.theta_hat,
                     f"{text}; its Estop is still latched ({why})")
    return Start("hold", checkpoint.q, checkpoint.wheel_turns, checkpoint.theta_hat, text)


def _refuse(q0, turns, why: str) -> Start:
    return Start("refuse", q0, turns, None, f"arming refused: {why}. Restart the controller with --pose scenario "
                                            "once the robot stands at the scenario's start pose")
