"""The demo's measurements from recorded messages (no processes)."""
import numpy as np
import pytest

from sharedctl.protocol.messages import Authority, LinkHealth, RobotState, SetClass
from sharedctl.services.demo.measure import Recorder, deviation, measure
from sharedctl.services.scenario_files import load

from .zenoh_fakes import Sample


def state(q, q_ref, authority, theta=(1.0, 0.0, 0.0)) -> RobotState:
    z = (0.0, 0.0, 0.0)
    return RobotState(
        seq=1, time=0.0, q=q, qd_hat=z, q_ref=q_ref, group_classes=(SetClass.SAFE,), active_group=None,
        authority=authority, k_s=1.0, k_h=1.0, k_f=0.0, u_h=z, u_f=z, u_s=z, wheel_torques=z, theta_hat=theta,
        min_margin=0.1, region_margins=(0.1,), estop_active=False, lease_holder="operator",
        link=LinkHealth(operator_latency_ms=0.0, loss_fraction=0.0, staleness_ms=0.0, can_feedback_age_ms=0.0),
    )


@pytest.fixture
def recorder():
    loop, _, _ = load("paper_convex").closed_loop()
    rec = Recorder(loop.feasible)
    for t, y in ((0.5, 3.0), (1.0, 4.2), (2.0, 3.9), (5.0, 3.9)):        # y = 4.2 is outside (y ≤ 4)
        q = np.array([-0.9, y, 0.0])
        rec.truth.append((t, q, np.array([0.3, 0.4, 0.0]), loop.feasible.contains(q), loop.feasible.margin(q)))
    H, M = Authority.HUMAN, Authority.MACHINE
    for t, auth, err in ((0.5, H, 0.0), (1.0, M, 0.3), (1.5, H, 0.4), (2.0, H, 0.0), (9.0, M, 9.0)):
        rec.states.append((t, state((-0.9, 3.0, 0.0), (-0.9, 3.0 + err, 0.0), auth)))
    return rec


def test_violations_count_ground_truth_samples_outside_the_set(recorder):
    assert measure(recorder, 0.0, 4.0)["violations"] == 1


def test_min_margin_is_the_smallest_slack_seen(recorder):
    assert measure(recorder, 0.0, 4.0)["min_margin"] == pytest.approx(-0.2)


def test_final_speed_and_pose_are_the_last_truth_sample_in_the_window(recorder):
    result = measure(recorder, 0.0, 4.0)
    assert result["final_speed"] == pytest.approx(0.5)
    assert result["final_pose"] == pytest.approx([-0.9, 3.9, 0.0])


def test_tracking_and_authority_come_from_telemetry_in_the_window(recorder):
    result = measure(recorder, 0.0, 4.0)
    assert result["steps"] == 4
    assert result["tracking_rmse"] == pytest.approx(np.sqrt((0.09 + 0.16) / 4))
    assert result["final_error"] == pytest.approx(0.0)
    assert result["human_authority"] == pytest.approx(0.75)
    assert result["switches"] == 2


def test_deviation_compares_final_pose_and_authority_share():
    run = {"final_pose": [0.0, 0.03, 0.0], "human_authority": 0.8, "tracking_rmse": 0.2, "min_margin": 0.01,
           "theta_hat": [1.0, 0.0, 0.0]}
    ref = {"final_pose": [0.04, 0.0, 0.0], "human_authority": 0.75, "tracking_rmse": 0.25, "min_margin": 0.02,
           "theta_hat": [1.0, 0.0, 0.0]}
    dev = deviation(run, ref)
    assert dev["final_pose_distance"] == pytest.approx(0.05)
    assert dev["human_authority_difference"] == pytest.approx(0.05)
    assert dev["within_tolerance"]


def test_without_friction_the_robot_plant_reference_is_the_model_plant_reference():
    from sharedctl.scenario import parse
    from sharedctl.services.demo.measure import plant_reference_run, reference_run

    data = dict(load("paper_convex").data, robot_sim={"friction_viscous": 0.0, "friction_coulomb": 0.0})
    scenario = parse(data)
    model_plant = reference_run(scenario, None, 2.0)
    robot_plant = plant_reference_run(scenario, None, 2.0)
    assert np.allclose(robot_plant["final_pose"], model_plant["final_pose"], atol=2e-3)
    assert robot_plant["human_authority"] == pytest.approx(model_plant["human_authority"])


def _sample(message) -> Sample:
    """A state message as the Recorder's callbacks see it."""
    from sharedctl.protocol.msgpack_codec import encode_message
    return Sample(encode_message(message))


def test_the_runs_t0_is_the_lease_instant_the_controller_reports_not_the_first_states_arrival():
    import dataclasses
    import time

    rec = Recorder(load("paper_convex").closed_loop()[0].feasible)
    granted = time.time() - 0.4                                    # the controller granted the lease 0.4 s ago
    rec.on_state(_sample(dataclasses.replace(state((0.0, 2.0, 0.0), (0.0, 2.0, 0.0), Authority.HUMAN),
                                             lease_since=granted)))
    assert rec.run_clock == "lease" and rec.lease_wall == granted
    assert time.monotonic() - rec.operator_start == pytest.approx(0.4, abs=0.05)


def test_without_a_reported_lease_instant_the_first_state_naming_a_holder_starts_the_clock():
    import time

    rec = Recorder(load("paper_convex").closed_loop()[0].feasible)
    rec.on_state(_sample(state((0.0, 2.0, 0.0), (0.0, 2.0, 0.0), Authority.HUMAN)))
    assert rec.run_clock == "first_state" and time.monotonic() - rec.operator_start == pytest.approx(0.0, abs=0.05)


def test_states_at_puts_the_ground_truth_on_the_runs_clock_by_simulation_time():
    import dataclasses

    from sharedctl.services.demo.measure import states_at

    rec = Recorder(load("paper_convex").closed_loop()[0].feasible)
    rec.operator_start, rec.lease_wall = 50.0, 1000.0              # t = 0: monotonic 50 s, wall 1000 s
    transit = [0.004, 0.0005, 0.02, 0.001]                         # arrival − simulation time: 0.5 ms at best
    for k, lag in enumerate(transit):
        sim = 11.98 + 0.01 * k                                     # the robot's clock: monotonic 40 s at 0
        q = np.array([0.0, 2.0 + 0.01 * k, 0.0])
        rec.truth.append((40.0 + sim + lag, q, np.array([0.0, 1.0, 0.0]), True, 1.0, sim))
        rec.truth_offset = min(rec.truth_offset, 40.0 + lag)
    for wall, torque in ((1001.95, 0.5), (1001.99, 0.7), (1002.02, 0.9)):
        rec.states.append((0.0, dataclasses.replace(state((0.0, 2.0, 0.0), (0.0, 2.0, 0.0), Authority.HUMAN),
                                                    time=wall, wheel_torques=(torque, 0.0, 0.0))))
    entry, = states_at(rec, [("controller.kill_at=2", 2.0)])
    assert [row[0] for row in entry["truth"]] == pytest.approx([1.9805, 1.9905, 2.0005, 2.0105])
    assert entry["truth"][2][1:4] == pytest.approx([0.0, 2.02, 0.0])
    assert [row[0] for row in entry["torques"]] == pytest.approx([1.95, 1.99])   # before the instant only
    assert entry["torques"][-1][1] == 0.7
