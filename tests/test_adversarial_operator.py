"""The adversarial operator (sharedctl.human.AdversarialOperator) and its packaged scenario."""
import tomllib
from importlib import resources

import numpy as np
import pytest

from sharedctl.human import AdversarialOperator, LineTrajectory
from sharedctl.metrics import summarize
from sharedctl.scenario import ScenarioError, parse
from sharedctl.simulator import simulate


def _scenario_data(**sharing):
    data = tomllib.loads(resources.files("sharedctl").joinpath("scenarios/adversarial_wall.toml").read_text())
    if sharing:
        data["sharing"] = sharing
    return data


def _run(data, duration=4.0):
    scenario = parse(data)
    loop, q0, v0 = scenario.closed_loop()
    return summarize(simulate(loop, q0, v0, duration, scenario.dt), scenario.dt)


def test_deflection_is_saturated_toward_the_target_whatever_the_robot_does():
    op = AdversarialOperator(LineTrajectory(np.zeros(3), np.zeros(3)), np.full(3, 20.0), np.array([0.3, 5.0, 0.0]))
    still = op.command(0.0, np.array([0.0, 2.0, 0.0]), np.zeros(3))
    rushing = op.command(0.0, np.array([0.0, 2.0, 0.0]), np.array([0.0, 3.0, 0.0]))
    np.testing.assert_allclose(still.deflection, [0.3, 1.0, 0.0])
    np.testing.assert_allclose(rushing.deflection, still.deflection)   # ignores the robot's speed
    assert still.intent == pytest.approx(0.5 * 20.0 * (0.09 + 1.0))


def test_alone_the_adversarial_operator_leaves_the_set():
    assert _run(_scenario_data(mode="human"))["violations"] > 0


def test_with_the_machine_the_adversarial_operator_cannot_leave_the_set():
    summary = _run(_scenario_data())
    assert summary["violations"] == 0 and summary["min_margin"] > 0.0


def test_a_non_positive_deflection_is_refused_naming_the_key():
    data = _scenario_data()
    data["human"]["deflection"] = 0.0
    with pytest.raises(ScenarioError, match="deflection"):
        parse(data)
