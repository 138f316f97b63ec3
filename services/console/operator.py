"""Turning an operator (scripted, at the keyboard or on a gamepad) into OperatorCommand messages.

The scripted operator is the scenario's human model (`sharedctl.human.ScriptedOperator`, the
paper's imitated human): at elapsed time t it reads the pose q and the estimated velocity q̇̂
from the latest RobotState, deflects the handle q̂_h = `human.command(t, q, q̇̂).deflection`
(44), and sends its wish (q_d, q̇_d, q̈_d) = `human.desired(t)`. The controller forms
u_h = k_p ∘ q̂_h and v_h (45) from it.

The wire carries a normalised deflection in [−1, 1]; the scripted handle is clipped to that
range. In the paper's scenarios it exceeds 1 only while the robot is held at a face (convex:
|q̂_h,y| ≤ 1.18, non-convex: |q̂_h,x| ≤ 1.28); the sampled simulation with the clip differs
from the unclipped one by 0.5 mm (convex) and 2.3 mm (non-convex) in final pose.
"""
from __future__ import annotations

import secrets
from dataclasses import dataclass, field

import numpy as np

from sharedctl.human import HumanModel
from sharedctl.protocol.messages import ControlRequest, OperatorCommand, RobotState

from ..lifecycle import steady_wall
from .keyboard import VirtualJoystick


def new_session_id() -> str:
    """A random token per console run (16 hex digits)."""
    return secrets.token_hex(8)


def clip_deflection(deflection) -> tuple[float, ...]:
    """The wire's normalised range [−1, 1] (NaN → 0: a command is never invalid)."""
    d = np.nan_to_num(np.asarray(deflection, float), nan=0.0, posinf=1.0, neginf=-1.0)
    return tuple(float(x) for x in np.clip(d, -1.0, 1.0))


@dataclass
class CommandCounter:
    """Who sends, the session, and the sequence number (increments per command)."""

    operator_id: str = "operator"
    session_id: str = field(default_factory=new_session_id)
    seq: int = 0

    def next(self) -> int:
        self.seq += 1
        return self.seq


@dataclass
class ScriptedCommandSource:
    """The scenario's human model, sampled at the command rate."""

    human: HumanModel
    counter: CommandCounter = field(default_factory=CommandCounter)

    def command(self, t: float, state: RobotState, *,
                estop: bool = False, send_time: float | None = None) -> OperatorCommand:
        """The command at elapsed time t (s since the script started) for the latest telemetry."""
        q = np.asarray(state.q, float)
        v = np.asarray(state.qd_hat, float)
        handle = self.human.command(t, q, v)
        wish = self.human.desired(t)
        return OperatorCommand(
            operator_id=self.counter.operator_id,
            session_id=self.counter.session_id,
            seq=self.counter.next(),
            send_time=steady_wall() if send_time is None else send_time,
            joystick=clip_deflection(handle.deflection),
            q_d=tuple(float(x) for x in wish.q),
            qd_d=tuple(float(x) for x in wish.q_dot),
            qdd_d=tuple(float(x) for x in wish.q_ddot),
            deadman=True,
            estop=estop,
            control_request=ControlRequest.NONE,
        )


@dataclass
class JoystickCommandSource:
    """A handle the operator deflects — the keyboard's virtual joystick or a gamepad (gamepad.py), both
    answering `deflection`, `wish`, `deadman`, `estop` and `control_request` — as commands: wish
    q_d = pose + reach ∘ deflection, at rest (q̇_d = q̈_d = 0)."""

    joystick: VirtualJoystick = field(default_factory=VirtualJoystick)
    counter: CommandCounter = field(default_factory=CommandCounter)

    def command(self, now: float, pose, *, send_time: float | None = None, hands_off: bool = False,
                estop: bool | None = None) -> OperatorCommand:
        """The command at monotonic time `now` for the latest pose estimate; `hands_off`: deadman released, no
        deflection, the wish at the pose (an estop request still goes out); `estop`: None is the joystick's."""
        pose = np.asarray(pose, float)
        deflection = self.joystick.deflection(now) * (0.0 if hands_off else 1.0)
        wish = pose if hands_off else self.joystick.wish(pose, now)
        zeros = tuple(0.0 for _ in pose)
        return OperatorCommand(
            operator_id=self.counter.operator_id,
            session_id=self.counter.session_id,
            seq=self.counter.next(),
            send_time=steady_wall() if send_time is None else send_time,
            joystick=clip_deflection(deflection),
            q_d=tuple(float(x) for x in wish),
            qd_d=zeros,
            qdd_d=zeros,
            deadman=self.joystick.deadman(now) and not hands_off,
            estop=self.joystick.estop if estop is None else estop,
            control_request=ControlRequest.NONE if hands_off else self.joystick.control_request(now),
        )
