"""The link impairments inject what they are set to: measured on seeded synthetic streams."""
from __future__ import annotations

import statistics

import pytest

from sharedctl.services.faults.impairments import (BernoulliLoss, Blackout, Corrupt, Delay, Duplicate, GilbertElliott,
                                                   Pipeline, RateLimit, Reorder, Replay, flip_bits)

N = 20_000
PERIOD = 0.01      # 100 Hz synthetic stream


def run(stages, n=N, period=PERIOD, seed=1):
    pipe = Pipeline(stages, seed=seed)
    out = []
    for i in range(n):
        t = i * period
        out.extend((t, i, release, payload) for release, payload in pipe.feed(t, i.to_bytes(4, "little")))
    return pipe, out


def test_bernoulli_loss_rate_is_the_setting():
    pipe, out = run([BernoulliLoss(0.3)])
    assert abs(1 - len(out) / N - 0.3) < 0.015
    assert pipe.counters["lost"] == N - len(out)


def test_gilbert_elliott_mean_burst_is_one_over_r_and_loss_is_p_over_p_plus_r():
    p, r = 0.02, 0.25
    _, out = run([GilbertElliott(p, r)], n=100_000)
    kept = {i for _, i, _, _ in out}
    bursts, length = [], 0
    for i in range(100_000):
        if i in kept:
            if length:
                bursts.append(length)
            length = 0
        else:
            length += 1
    assert abs(statistics.mean(bursts) - 1 / r) < 0.25           # 4 messages
    assert abs(1 - len(kept) / 100_000 - p / (p + r)) < 0.01     # 7.4 %


def test_blackout_drops_exactly_the_window():
    pipe, out = run([Blackout([(2.0, 0.5)])], n=400)
    lost = sorted(set(range(400)) - {i for _, i, _, _ in out})
    assert lost == list(range(200, 250))
    assert pipe.counters["blackout_dropped"] == 50


def test_fixed_delay_is_exact():
    _, out = run([Delay(0.3)], n=100)
    assert all(release - t == pytest.approx(0.3) for t, _, release, _ in out)


@pytest.mark.parametrize("dist,mean,stdev", [("uniform", 0.1, 0.05 / 3 ** 0.5), ("normal", 0.1, 0.02)])
def test_symmetric_jitter_has_the_set_mean_and_spread(dist, mean, stdev):
    # sparse arrivals (1 s apart) so the order-preserving rule never holds a message back
    _, out = run([Delay(0.1, 0.05 if dist == "uniform" else 0.02, dist)], n=5000, period=1.0)
    delays = [release - t for t, _, release, _ in out]
    assert abs(statistics.mean(delays) - mean) < 0.002
    assert abs(statistics.stdev(delays) - stdev) < 0.002
    if dist == "uniform":
        assert 0.05 <= min(delays) and max(delays) <= 0.15


def test_pareto_jitter_is_non_negative_heavy_tailed_with_the_set_mean():
    _, out = run([Delay(0.0, 0.05, "pareto")], n=20_000, period=1.0)
    extra = [release - t for t, _, release, _ in out]
    assert min(extra) >= 0
    assert abs(statistics.mean(extra) - 0.05) < 0.005
    assert max(extra) > 10 * 0.05      # a heavy tail: some messages are very late


def test_delay_never_reorders():
    _, out = run([Delay(0.05, 0.05, "normal")], n=5000, period=0.002)
    releases = [release for _, _, release, _ in sorted(out, key=lambda x: x[1])]
    assert releases == sorted(releases)


def test_duplicate_rate_is_the_setting():
    pipe, out = run([Duplicate(0.2)])
    assert abs(len(out) / N - 1.2) < 0.015
    assert pipe.counters["duplicated"] == len(out) - N


def test_reorder_holds_back_the_set_fraction_and_later_messages_overtake():
    pipe, out = run([Reorder(0.1, 0.055)], n=10_000)
    assert abs(pipe.counters["held_back"] / 10_000 - 0.1) < 0.01
    overtaken, newest = 0, -1
    for _, i, _, _ in sorted(out, key=lambda x: (x[2], x[1])):
        overtaken += i < newest
        newest = max(newest, i)
    held = [i for t, i, release, _ in out if release > t]
    assert len(held) == pipe.counters["held_back"]
    # a 55 ms hold at 10 ms spacing: a held message is overtaken by any of the next 5 that was not held
    held_set = set(held)
    assert overtaken == sum(1 for i in held if any(j not in held_set and j < 10_000 for j in range(i + 1, i + 6)))
    assert overtaken > 0.9 * len(held)


def test_corrupt_flips_exactly_the_set_number_of_bits():
    pipe, out = run([Corrupt(0.5, bits=3)], n=4000)
    flipped = [bin(int.from_bytes(payload, "little") ^ i).count("1") for _, i, _, payload in out]
    assert set(flipped) == {0, 3}
    assert abs(flipped.count(3) / 4000 - 0.5) < 0.03
    assert pipe.counters["bits_flipped"] == 3 * flipped.count(3)


def test_corrupt_leaves_a_protected_header_alone():
    stage = Corrupt(1.0, bits=8, skip=4)
    pipe = Pipeline([stage], seed=3)
    for _ in range(200):
        (_, payload), = pipe.feed(0.0, b"HEAD\x00\x00")
        assert payload[:4] == b"HEAD" and payload[4:] != b"\x00\x00"


def test_flip_bits_with_more_bits_than_the_payload_inverts_it():
    import random
    assert flip_bits(b"\x0f", 20, random.Random(0)) == b"\xf0"


def test_rate_limit_spaces_messages_and_tail_drops_behind_the_queue():
    pipe, out = run([RateLimit(50.0, queue=10)], n=1000)    # 100 Hz into 50 Hz
    releases = [release for _, _, release, _ in out]
    gaps = [b - a for a, b in zip(releases, releases[1:])]
    assert min(gaps) == pytest.approx(0.02)
    assert abs(len(out) / 1000 - 0.5) < 0.02
    assert pipe.counters["rate_dropped"] == 1000 - len(out)


def test_replay_resends_messages_at_least_the_set_age_old():
    pipe, out = run([Replay(0.1, 0.5)], n=5000)
    stale = [(t, int.from_bytes(payload, "little")) for t, i, _, payload in out
             if int.from_bytes(payload, "little") != i]
    assert abs(len(stale) / 5000 - 0.1) < 0.015
    assert pipe.counters["replayed"] == len(stale)
    assert all(t - k * PERIOD >= 0.5 - 1e-9 for t, k in stale)
    assert all(t - k * PERIOD <= 0.5 + PERIOD + 1e-9 for t, k in stale)


def test_a_pipeline_is_reproducible_from_its_seed_and_composes_stages():
    def stages():
        return [BernoulliLoss(0.1), Duplicate(0.1), Corrupt(0.1), Delay(0.02, 0.01, "normal"), Reorder(0.05, 0.03)]
    a = run(stages(), n=3000, seed="7:operator")[1]
    b = run(stages(), n=3000, seed="7:operator")[1]
    c = run(stages(), n=3000, seed="8:operator")[1]
    assert a == b and a != c
    pipe = run(stages(), n=3000, seed="7:operator")[0]
    for key in ("lost", "duplicated", "corrupted", "delayed", "held_back"):
        assert pipe.counters[key] > 0
