"""The predictor's input (shared_controller.in_flight): over the loop delay, each command counts for the
time it acted — a tick that comes late (a loaded host) holds its command longer than a period, and the
state the step runs on must be where the commands, as they were held, take the robot."""
import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sharedctl.services.scenario_files import load
from sharedctl.sharing import Mode
from sharedctl.shared_controller import OperatorInput, SharedController, in_flight, predict
from sharedctl.transform import Desired

PERIOD = 0.002

helds = st.lists(st.floats(0.0005, 0.012), min_size=1, max_size=40)


@settings(max_examples=300, deadline=None)
@given(helds, st.floats(0.0, 0.15))
def test_the_commands_in_flight_are_the_newest_each_over_its_own_time_the_oldest_cut_to_the_delay(held, delay):
    sent = tuple(range(len(held)))
    held = tuple(held)
    commands, spans = in_flight(sent, held, delay)
    k = len(commands)
    assert commands == sent[len(sent) - k:] and len(spans) == k
    if delay <= 1e-6:
        assert k == 0
        return
    assert sum(spans) == pytest.approx(min(delay, sum(held)), abs=2e-6)
    assert spans[1:] == held[len(held) - k + 1:]              # every command but the oldest over its whole time
    assert 0.0 < spans[0] <= held[len(held) - k]               # the oldest at most over its own


@pytest.mark.parametrize("lag", [0, 1, 2, 7, 20, 64])
def test_with_every_command_held_one_period_a_delay_of_k_periods_is_the_last_k_commands(lag):
    """The uniform case, to the bit: what the batched predictor (integer lags) runs."""
    sent = tuple(np.array([float(i), 0.0, 0.0]) for i in range(64))
    commands, spans = in_flight(sent, (PERIOD,) * 64, lag * PERIOD)
    assert [c[0] for c in commands] == [c[0] for c in sent[64 - lag:]] and spans == (PERIOD,) * lag


def _late_tick_history():
    """Pushing at the face y = 4 for 12 periods, then braking for 4, then a brake held 12 ms (the next tick came
    late): the last 40 ms were 20 ms of push and 20 ms of brake."""
    push, brake = np.array([0.0, 20.0, 0.0]), np.array([0.0, -20.0, 0.0])
    sent = (push,) * 12 + (brake,) * 5
    held = (PERIOD,) * 16            # the newest acted `elapsed`, 12 ms
    return sent, held, 0.012, 0.040


def _exact(model, q, v, timeline):
    """The omnidirectional robot at zero yaw rate under piecewise-constant force: constant acceleration per piece."""
    q, v = np.array(q, float), np.array(v, float)
    for u, h in timeline:
        a = model.acceleration(q, v, u)
        q, v = q + v * h + 0.5 * a * h * h, v + a * h
    return q, v


def test_after_a_late_tick_the_prediction_is_where_the_commands_as_held_take_the_robot():
    loop, _, _ = load("paper_convex").closed_loop("ce")
    model = loop.model
    sent, held, elapsed, delay = _late_tick_history()
    q, v = np.array([0.0, 3.5, 0.0]), np.array([0.0, 0.8, 0.0])
    commands, spans = in_flight(sent, held + (elapsed,), delay)
    assert len(commands) == 15 and spans == (PERIOD,) * 14 + (elapsed,)
    truth = _exact(model, q, v, [(u, PERIOD) for u in sent[2:16]] + [(sent[-1], elapsed)])
    q_p, v_p = predict(model, q, v, commands, spans)
    assert np.allclose(q_p, truth[0], rtol=0, atol=1e-12) and np.allclose(v_p, truth[1], rtol=0, atol=1e-12)
    # a count of periods (round(delay / dt) commands, each held the step's dt, cut to 4 periods) replays the
    # last five commands, all brakes, over the whole delay: it under-states the speed at the face by what the
    # 20 ms of push it leaves out added — the barrier would brake for a robot slower than the real one
    dt = min(elapsed, 4 * PERIOD)
    _, v_counted = predict(model, q, v, sent[-int(round(delay / dt)):], dt)
    assert v_counted[1] < truth[1][1] - 0.04


def test_the_step_runs_on_the_state_its_commands_reach_over_the_time_the_last_one_acted():
    """`elapsed` beyond the four periods the laws integrate over (`dt`) still counts for the prediction."""
    loop, _, _ = load("paper_convex").closed_loop("ce")
    sharing = dataclasses.replace(loop.sharing, mode=Mode.MACHINE)
    ctrl = SharedController(loop.model, loop.feasible, loop.controller, sharing, loop.reference)
    sent, held, elapsed, delay = _late_tick_history()
    q, v = np.array([0.0, 3.5, 0.0]), np.array([0.0, 0.8, 0.0])
    start = ctrl.initial_state(q)
    operator = OperatorInput(Desired(np.array([0.0, 3.0, 0.0]), np.zeros(3), np.zeros(3)), np.zeros(3), 0.0)
    late = dataclasses.replace(start, sent=sent, held=held)
    _, out = ctrl.step(late, q, v, operator, 4 * PERIOD, delay, elapsed)
    q_t, v_t = _exact(loop.model, q, v, [(u, PERIOD) for u in sent[2:16]] + [(sent[-1], elapsed)])
    _, seen = ctrl.step(start, q_t, v_t, operator, 4 * PERIOD)          # no history: no prediction
    assert np.allclose(out.u_s, seen.u_s, rtol=0, atol=1e-9)
    _, counted = ctrl.step(late, q, v, operator, 4 * PERIOD, delay)   # the last command taken as held dt
    assert not np.allclose(counted.u_s, seen.u_s, rtol=0, atol=1e-3)


def test_the_history_keeps_each_commands_time_aligned_with_it_up_to_its_length():
    loop, q0, _ = load("paper_convex").closed_loop("ce")
    ctrl = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference)
    state = ctrl.initial_state(q0)
    operator = OperatorInput(Desired(q0, np.zeros(3), np.zeros(3)), np.zeros(3), 0.0)
    times = [PERIOD * (1 + (k % 5)) for k in range(80)]
    for k, h in enumerate(times):
        state, _ = ctrl.step(state, q0, np.zeros(3), operator, PERIOD, 0.0, h)
        assert len(state.held) == len(state.sent) - 1
        # the command sent at step j acted until step j + 1, for times[j + 1]; the newest's time is still open
        assert state.held == tuple(times[max(1, k + 1 - 63):k + 1])
    assert len(state.sent) == 64
