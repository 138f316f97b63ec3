"""The demo's measurements from recorded messages (no processes)."""
import numpy as np
import pytest

from sharedctl.protocol.messages import Authority, LinkHealth, RobotState, SetClass
from sharedctl.services.demo.measure import Recorder, deviation, measure
from sharedctl.services.scenario_files import load


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
