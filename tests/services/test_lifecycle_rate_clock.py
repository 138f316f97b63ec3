"""RateClock (services/lifecycle.py) on a fake clock: absolute deadlines, missed ticks, and the polled
stretch before each deadline (`spin`): how long it sleeps and how long it polls."""
import pytest

from sharedctl.services import lifecycle
from sharedctl.services.lifecycle import RateClock


class FakeTime:
    """monotonic() advances by `poll` per call (a polling loop makes progress); sleep() adds its argument."""

    def __init__(self, poll=1e-6):
        self.now, self.poll, self.slept, self.polls = 100.0, poll, [], 0

    def monotonic(self):
        self.now += self.poll
        self.polls += 1
        return self.now

    def sleep(self, seconds):
        self.slept.append(seconds)
        self.now += seconds


@pytest.fixture
def fake(monkeypatch):
    t = FakeTime()
    monkeypatch.setattr(lifecycle, "time", t)
    return t


def test_without_spin_it_sleeps_to_the_deadline_and_never_polls(fake):
    clock = RateClock(0.002)
    deadline = clock.next
    fake.polls = 0
    clock.wait()
    assert fake.slept[-1] == pytest.approx(deadline - (deadline - 0.002) - 2e-6, abs=1e-5)
    assert fake.polls == 2 and fake.now >= deadline


def test_with_spin_it_sleeps_until_spin_before_the_deadline_then_polls_to_it(fake):
    clock = RateClock(0.002, spin=1e-4)
    deadline = clock.next
    clock.wait()
    assert fake.slept[-1] == pytest.approx(0.002 - 1e-4, abs=1e-5)
    assert fake.now >= deadline and fake.now - deadline < 1e-5      # polled up to the deadline, not beyond
    assert clock.next == pytest.approx(deadline + 0.002, abs=1e-12)  # absolute deadlines: no drift


def test_ticks_overrun_by_more_than_a_period_are_counted_as_missed(fake):
    clock = RateClock(0.002, spin=1e-4)
    fake.now += 0.0075                  # the loop stalled through three deadlines
    lateness = clock.wait()
    assert clock.missed == 2 and 0.0 <= lateness < 0.002


def test_a_negative_spin_is_refused():
    with pytest.raises(ValueError):
        RateClock(0.002, spin=-1e-4)


def test_poll_until_polls_to_the_instant_and_never_sleeps(fake):
    lifecycle.poll_until(100.010)
    assert fake.slept == []
    assert 100.010 <= fake.now < 100.010 + 2e-6


def test_poll_until_an_instant_that_has_passed_returns_at_once(fake):
    lifecycle.poll_until(99.0)
    assert fake.slept == [] and fake.polls == 1
