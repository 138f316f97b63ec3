"""Replay and ordering: per-session sequence numbers and send-time age (services/controller/replay_guard.py)."""
import pytest

from sharedctl.services.controller.replay_guard import ReplayGuard

SKEW = 37.25     # s: the sender's clock is this far behind the controller's (unsynchronised hosts)


def admit(guard, seq, sent, received, session="s1"):
    """A message sent at `sent` (sender clock) and received at `received` (controller monotonic = wall here)."""
    return guard.admit(session, seq, sent - SKEW, received, received)


def test_newer_seqs_are_taken_duplicates_and_older_ones_dropped():
    guard = ReplayGuard()
    assert admit(guard, 5, 0.0, 0.01) is None
    assert admit(guard, 5, 0.0, 0.02) == "duplicate_seq"
    assert admit(guard, 4, 0.0, 0.03) == "out_of_order_seq"
    assert admit(guard, 6, 0.02, 0.03) is None


def test_sessions_have_their_own_sequences():
    guard = ReplayGuard()
    assert admit(guard, 100, 0.0, 0.01, session="old") is None
    assert admit(guard, 1, 0.0, 0.01, session="new") is None


def test_a_clock_offset_between_hosts_alone_is_not_staleness():
    guard = ReplayGuard(max_age=0.5)
    for k in range(50):                                   # 37 s of skew, 10 ms of delay: all taken
        assert admit(guard, k + 1, 0.02 * k, 0.02 * k + 0.01) is None


def test_a_message_held_back_longer_than_the_age_limit_is_stale():
    guard = ReplayGuard(max_age=0.5)
    for k in range(10):
        admit(guard, k + 1, 0.02 * k, 0.02 * k + 0.01)
    assert admit(guard, 11, 0.2, 0.2 + 0.01 + 0.6) == "stale"      # 0.6 s later than the best delivery
    assert admit(guard, 12, 0.22, 0.22 + 0.01 + 0.4) is None        # 0.4 s: within the limit
    assert guard.age("s1", 0.3 - SKEW, 0.9, 0.9) == pytest.approx(0.59)


def test_a_constant_delay_is_not_staleness():
    guard = ReplayGuard(max_age=0.5)
    for k in range(20):
        assert admit(guard, k + 1, 0.02 * k, 0.02 * k + 0.8) is None   # 800 ms every time


def test_the_reference_follows_the_window_so_a_lasting_delay_change_recovers():
    guard = ReplayGuard(max_age=0.5, window=10.0)
    admit(guard, 1, 0.0, 0.01)
    assert admit(guard, 2, 1.0, 1.71) == "stale"
    assert admit(guard, 3, 12.0, 12.71) is None           # the 0.01 s delivery left the 10 s window


def test_the_optional_skew_bound_refuses_far_off_send_times():
    guard = ReplayGuard(max_skew=2.0)
    assert guard.admit("s1", 1, 1000.0 - 2.5, 1.0, 1000.0) == "clock_skew"
    assert guard.admit("s1", 1, 1000.0 - 0.1, 1.0, 1000.0) is None


def test_without_a_receive_wall_time_only_the_order_is_checked():
    guard = ReplayGuard()
    assert guard.admit("s1", 1, 5.0, 0.0, None) is None
    assert guard.admit("s1", 1, 5.0, 0.0, None) == "duplicate_seq"


def test_remembered_sessions_are_bounded():
    guard = ReplayGuard(max_sessions=4)
    for k in range(10):
        admit(guard, 1, 0.0, 0.01, session=f"s{k}")
    assert guard.sessions == 4


def test_limits_must_be_positive():
    with pytest.raises(ValueError):
        ReplayGuard(max_age=0.0)
    with pytest.raises(ValueError):
        ReplayGuard(max_skew=-1.0)


def test_a_pinned_session_outlives_any_flood_of_other_sessions():
    guard = ReplayGuard(max_sessions=4)
    admit(guard, 5, 0.0, 0.01, session="holder")
    guard.pin("holder")
    for k in range(100):
        admit(guard, 1, 0.0, 0.01, session=f"junk{k}")
    assert guard.sessions == 5                                   # 4 unpinned and the pinned one
    assert admit(guard, 5, 0.0, 0.01, session="holder") == "duplicate_seq"
    assert admit(guard, 6, 0.0, 0.01, session="holder") is None


def test_pins_are_bounded_too_and_a_dropped_pin_is_forgotten_like_any_session():
    guard = ReplayGuard(max_sessions=2)
    for k in range(5):
        admit(guard, 1, 0.0, 0.01, session=f"p{k}")
        guard.pin(f"p{k}")
    for k in range(10):
        admit(guard, 1, 0.0, 0.01, session=f"junk{k}")
    assert guard.sessions == 4                                   # 2 pinned (the newest pins), 2 unpinned
    assert admit(guard, 1, 0.0, 0.01, session="p4") == "duplicate_seq"


@pytest.mark.parametrize("step", [0.6, 1.0, 2.0, -0.6, -2.0])
def test_a_step_of_the_controllers_wall_clock_rejects_nothing(step):
    """Threat: a wall-clock step of 0.5–2 s on the controller's host made every command look that much later
    than the session's best delivery — stale for the 10 s window (docs/security.md). Ages run on the
    monotonic receive time now; only the optional skew bound reads the wall clock."""
    guard = ReplayGuard(max_age=0.5)
    for k in range(100):                                    # 50 Hz; the wall clock steps at k = 50
        mono = 0.02 * k + 0.01
        wall = 5000.0 + mono + (step if k >= 50 else 0.0)
        assert guard.admit("s1", k + 1, 0.02 * k - SKEW, mono, wall) is None, k
