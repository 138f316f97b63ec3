"""One simulated ODrive axis (firmware 0.6 behaviour, as far as sharedctl uses it). Pure: no I/O.

The axis answers typed CANSimple frames (`sharedctl.protocol.cansimple`) and keeps the state a
real drive keeps: axis state, control/input mode, active errors, the last disarm reason, the
torque setpoint and limits, and a watchdog.

Behaviour (what the controller daemon can rely on):
* Starts IDLE, no errors, control mode POSITION_CONTROL / input PASSTHROUGH (ODrive's defaults),
  so a drive produces no torque until it is told TORQUE_CONTROL + PASSTHROUGH and armed.
* Set_Axis_State CLOSED_LOOP_CONTROL arms the axis only when no error is active; with an active
  error the request is refused (state stays IDLE, procedure result DISARMED). IDLE is always
  accepted. Other states (calibration and the like) complete at once: the axis ends IDLE,
  procedure result SUCCESS. Arming and disarming reset the torque setpoint to 0.
* Torque reaches the wheel only in CLOSED_LOOP_CONTROL with TORQUE_CONTROL and PASSTHROUGH (or
  TORQUE_RAMP, treated as passthrough); it is clamped to the axis torque limit
  (min(torque limit, k_t · current limit)) and, above the velocity limit, the axis gives no
  further accelerating torque. Other control modes are recorded but produce no torque.
* Set_Input_Torque sets the setpoint; Set_Input_Vel sets the velocity setpoint and, as on ODrive,
  the torque setpoint to its Input_Torque_FF. Both feed the watchdog.
* Watchdog (on by default, 0.1 s): it runs while the axis is in CLOSED_LOOP_CONTROL and is fed
  when the axis is armed and by every Set_Input_Torque/Set_Input_Vel. On expiry: error
  WATCHDOG_TIMER_EXPIRED, disarm reason WATCHDOG_TIMER_EXPIRED, state IDLE, torque 0.
* Estop: error ESTOP_REQUESTED, state IDLE, torque 0.
* Clear_Errors: clears the active errors (the axis stays IDLE; it must be re-armed). The disarm
  reason is kept until the next successful arm, as on ODrive 0.6.
* Polls (RTR) of every Get_* frame are answered with the current values; the heartbeat and the
  encoder estimates are also sent cyclically by the caller (`heartbeat()`, `encoder_estimates()`).
* `restart()`: what a drive that lost power or reset comes back as — IDLE, no errors, ODrive's
  default modes, torque 0, watchdog fed, and its incremental encoder counting from 0 where the
  wheel stands (the caller keeps it silent for the boot).

Motor model: iq = τ / k_t with k_t = 0.5 N·m/A (a direct-drive hub motor); DC bus 24 V; bus
current = mechanical power τ·ω / 24 V (no losses, negative when the wheel is braking).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.odrive_enums import AxisState, CommandId, ControlMode, InputMode, ODriveError, ProcedureResult

TORQUE_CONSTANT = 0.5      # k_t, N·m/A
BUS_VOLTAGE = 24.0         # V
TWO_PI = 2.0 * math.pi

_TORQUE_INPUT_MODES = (InputMode.PASSTHROUGH, InputMode.TORQUE_RAMP)


@dataclass(frozen=True)
class AxisConfig:
    """Per-axis settings (the robot's `[robot_sim]` values)."""

    torque_limit: float = 60.0               # N·m
    watchdog_timeout: float = 0.1            # s; 0 or less disables the watchdog
    torque_constant: float = TORQUE_CONSTANT  # N·m/A
    bus_voltage: float = BUS_VOLTAGE         # V


class Axis:
    """State machine of one ODrive axis; `handle` frames, `tick` the watchdog, read `applied_torque`."""

    def __init__(self, node_id: int, config: AxisConfig = AxisConfig()) -> None:
        self.node_id = node_id
        self.config = config
        self.state = AxisState.IDLE
        self.control_mode = ControlMode.POSITION_CONTROL
        self.input_mode = InputMode.PASSTHROUGH
        self.errors = ODriveError.NONE
        self.disarm_reason = ODriveError.NONE
        self.procedure_result = ProcedureResult.SUCCESS
        self.input_torque = 0.0                  # N·m, setpoint
        self.input_vel = 0.0                     # turns/s, recorded only
        self.velocity_limit = math.inf           # turns/s
        self.current_limit = config.torque_limit / config.torque_constant  # A
        self.watchdog_enabled = config.watchdog_timeout > 0
        self.last_feed = -math.inf               # s
        self.watchdog_trips = 0
        self.pos_turns = 0.0                     # encoder feedback, set by the caller
        self.vel_turns_s = 0.0
        self.origin = 0.0                        # turns of the wheel where the encoder reads 0 (`restart`)
        self.restarts = 0

    # ----- state -----------------------------------------------------------------
    @property
    def armed(self) -> bool:
        return self.state == AxisState.CLOSED_LOOP_CONTROL

    @property
    def torque_limit(self) -> float:
        """N·m: the configured limit, lowered by Set_Limits' current limit."""
        return min(self.config.torque_limit, self.config.torque_constant * self.current_limit)

    def set_feedback(self, pos_turns: float, vel_turns_s: float) -> None:
        """Encoder position (turns) and velocity (turns/s) of the wheel, from the plant."""
        self.pos_turns = pos_turns - self.origin
        self.vel_turns_s = vel_turns_s

    def power_off(self) -> None:
        """The drive loses power: disarmed (its brake engages), torque 0; `restart` brings it back."""
        self._disarm()

    def restart(self, wheel_turns: float, now: float) -> None:
        """Back from a reset with the wheel at `wheel_turns`: see the module doc."""
        self.state, self.errors, self.disarm_reason = AxisState.IDLE, ODriveError.NONE, ODriveError.NONE
        self.control_mode, self.input_mode = ControlMode.POSITION_CONTROL, InputMode.PASSTHROUGH
        self.procedure_result = ProcedureResult.SUCCESS
        self.input_torque = self.input_vel = 0.0
        self.velocity_limit = math.inf
        self.current_limit = self.config.torque_limit / self.config.torque_constant
        self.last_feed = now
        self.origin = wheel_turns
        self.pos_turns = 0.0
        self.restarts += 1

    def torque_target(self) -> float:
        """The torque the controller asks for (N·m): the setpoint in torque mode when armed, else 0."""
        if self.armed and self.control_mode == ControlMode.TORQUE_CONTROL and self.input_mode in _TORQUE_INPUT_MODES:
            return self.input_torque
        return 0.0

    def applied_torque(self) -> float:
        """The torque the motor produces (N·m): 0 unless armed in torque mode; clamped to the limit."""
        target = self.torque_target()
        if target == 0.0:
            return 0.0
        limit = self.torque_limit
        tau = max(-limit, min(limit, target))
        if abs(self.vel_turns_s) >= self.velocity_limit and tau * self.vel_turns_s > 0:
            return 0.0  # above the velocity limit: no further accelerating torque
        return tau

    def _arm(self, now: float) -> None:
        if self.errors:
            self.procedure_result = ProcedureResult.DISARMED
            self.state = AxisState.IDLE
            return
        self.state = AxisState.CLOSED_LOOP_CONTROL
        self.procedure_result = ProcedureResult.SUCCESS
        self.disarm_reason = ODriveError.NONE
        self.input_torque = 0.0
        self.last_feed = now

    def _disarm(self, error: ODriveError = ODriveError.NONE) -> None:
        if error:
            self.errors |= error
            self.disarm_reason = error
            if self.armed:
                self.procedure_result = ProcedureResult.DISARMED
        self.state = AxisState.IDLE
        self.input_torque = 0.0

    def tick(self, now: float) -> bool:
        """Run the watchdog at time `now` (s); True if it tripped just now."""
        if self.watchdog_enabled and self.armed and now - self.last_feed > self.config.watchdog_timeout:
            self._disarm(ODriveError.WATCHDOG_TIMER_EXPIRED)
            self.watchdog_trips += 1
            return True
        return False

    # ----- frames ----------------------------------------------------------------
    def handle(self, frame: object, now: float) -> list:
        """Apply one received frame addressed to this axis; return the reply frames (for polls)."""
        if isinstance(frame, cs.SetInputTorque):
            assert math.isfinite(frame.input_torque)
            self.input_torque = frame.input_torque
            self.last_feed = now
        elif isinstance(frame, cs.SetInputVel):
            assert math.isfinite(frame.input_vel) and math.isfinite(frame.input_torque_ff)
            self.input_vel = frame.input_vel
            self.input_torque = frame.input_torque_ff
            self.last_feed = now
        elif isinstance(frame, cs.SetAxisState):
            requested = frame.requested_state
            if requested == AxisState.CLOSED_LOOP_CONTROL:
                if not self.armed:
                    self._arm(now)
            elif requested != AxisState.UNDEFINED:
                self._disarm()
                self.procedure_result = ProcedureResult.SUCCESS
        elif isinstance(frame, cs.SetControllerMode):
            self.control_mode = frame.control_mode
            self.input_mode = frame.input_mode
        elif isinstance(frame, cs.Estop):
            self._disarm(ODriveError.ESTOP_REQUESTED)
        elif isinstance(frame, cs.ClearErrors):
            self.errors = ODriveError.NONE
        elif isinstance(frame, cs.SetLimits):
            self.velocity_limit = frame.velocity_limit
            self.current_limit = frame.current_limit
        elif isinstance(frame, cs.PollRequest):
            return [self.feedback(frame.command)]
        return []

    def heartbeat(self) -> cs.Heartbeat:
        return cs.Heartbeat(self.node_id, self.errors, self.state, self.procedure_result, True)

    def encoder_estimates(self) -> cs.GetEncoderEstimates:
        return cs.GetEncoderEstimates(self.node_id, self.pos_turns, self.vel_turns_s)

    def feedback(self, command: CommandId):
        """The Get_* frame `command` with the current values (what an RTR poll returns)."""
        k_t = self.config.torque_constant
        if command == CommandId.GET_ENCODER_ESTIMATES:
            return self.encoder_estimates()
        if command == CommandId.GET_ERROR:
            return cs.GetError(self.node_id, self.errors, self.disarm_reason)
        if command == CommandId.GET_IQ:
            return cs.GetIq(self.node_id, self.torque_target() / k_t, self.applied_torque() / k_t)
        if command == CommandId.GET_TORQUES:
            return cs.GetTorques(self.node_id, self.torque_target(), self.applied_torque())
        if command == CommandId.GET_BUS_VOLTAGE_CURRENT:
            power = self.applied_torque() * self.vel_turns_s * TWO_PI  # W
            return cs.GetBusVoltageCurrent(self.node_id, self.config.bus_voltage, power / self.config.bus_voltage)
        raise ValueError(f"{command!r} is not a Get_* frame")
