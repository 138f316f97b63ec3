"""Sensor-synchronous ticks (services/controller/phase.py): the phase lock's corrections."""
from __future__ import annotations

import pytest

from sharedctl.services.controller.odometry import AxisEstimate
from sharedctl.services.controller.phase import SensorPhaseLock, estimates_arrival

T = 0.002


def test_no_correction_when_ticks_already_follow_the_estimates_by_the_lead():
    lock = SensorPhaseLock(T)
    assert lock.correction(10.0 + lock.lead, 10.0) == pytest.approx(0.0, abs=1e-12)
    assert lock.correction(10.0 + lock.lead + 3 * T, 10.0) == pytest.approx(0.0, abs=1e-9)


def test_a_late_phase_is_pulled_earlier_and_an_early_one_later_by_at_most_max_step():
    lock = SensorPhaseLock(T)
    assert lock.correction(10.0 + lock.lead + 1e-4, 10.0) == pytest.approx(-lock.gain * 1e-4)
    assert lock.correction(10.0 + lock.lead - 1e-4, 10.0) == pytest.approx(lock.gain * 1e-4)
    assert lock.correction(10.0 + lock.lead + 0.9e-3, 10.0) == -lock.max_step
    assert lock.correction(10.0 + lock.lead + 1.1e-3, 10.0) == lock.max_step     # closer the other way round


def test_repeated_corrections_lock_the_phase():
    lock, arrival, next_tick = SensorPhaseLock(T), 0.000321, 0.0013
    for _ in range(400):
        next_tick += lock.correction(next_tick, arrival) + T
        arrival += T
    assert (next_tick - arrival - lock.lead) % T == pytest.approx(0.0, abs=1e-7)


def test_arrival_needs_every_wheel():
    assert estimates_arrival([AxisEstimate(0.0, 0.0, 1.0), None, AxisEstimate(0.0, 0.0, 2.0)]) is None
    assert estimates_arrival([AxisEstimate(0.0, 0.0, 1.0), AxisEstimate(0.0, 0.0, 1.5)]) == 1.5
