"""Seeded, composable link impairments in the spirit of Linux `tc netem` — a pure model.

A :class:`Pipeline` maps one arrival ``(t, payload)`` (``t`` in seconds from the run's start)
to a list of ``(release_time, payload)``: nothing (lost), one message, or several (duplicated,
replayed). It keeps counters of what it did, so a fault run can prove each fault was injected.
No clocks, sockets or threads: the Zenoh relay and the CAN gateway feed it arrival times and
release what it returns when the time comes; tests feed it synthetic streams.

Stages, applied in this fixed order (each one may be absent):

=================  ===========================================================================
``Blackout``       every message arriving in ``[start, start + duration)`` is dropped (a dead link)
``BernoulliLoss``  each message is dropped with probability ``p`` (independent)
``GilbertElliott`` two-state burst loss (Gilbert): Good→Bad with probability ``p`` per message,
                   Bad→Good with ``r``; messages in Bad are lost. Mean burst length ``1/r``,
                   long-run loss ``p/(p+r)``
``Duplicate``      with probability ``p`` a second copy follows the message
``Corrupt``        with probability ``p`` ``bits`` distinct random bits of the payload are flipped
``Replay``         with probability ``p`` a stale copy of a message received at least ``age``
                   seconds earlier is sent as well (an old command or state arriving again)
``Delay``          fixed delay plus jitter, uniform ``U(-j, +j)``, normal ``N(0, j²)`` (both
                   clipped so the total is ≥ 0) or Pareto (non-negative, heavy-tailed, mean ``j``,
                   shape 2.5). Order-preserving, as on the TCP link Zenoh uses: a message is never
                   released before the one that arrived before it
``Reorder``        with probability ``p`` a message is held back ``gap`` seconds more, so later
                   messages overtake it
``RateLimit``      at most ``rate`` messages per second, serialised (each occupies ``1/rate`` s);
                   a message that would wait behind more than ``queue`` others is tail-dropped
=================  ===========================================================================

Every stage takes the pipeline's ``random.Random`` (seeded per stream), so a run is
reproducible from its seed.
"""
from __future__ import annotations

import random
from collections import deque

Item = tuple[float, bytes]          # (release time s, payload)

PARETO_SHAPE = 2.5


class Stage:
    """One impairment: ``process(t, items, rng, counters) -> items``."""

    name = "stage"

    def process(self, t: float, items: list[Item], rng: random.Random, counters: dict) -> list[Item]:
        raise NotImplementedError


def _count(counters: dict, key: str, n: int | float = 1) -> None:
    counters[key] = counters.get(key, 0) + n


class Blackout(Stage):
    name = "blackout"

    def __init__(self, windows: list[tuple[float, float]]) -> None:
        self.windows = [(float(s), float(s) + float(d)) for s, d in windows]

    def active(self, t: float) -> bool:
        return any(a <= t < b for a, b in self.windows)

    def process(self, t, items, rng, counters):
        if items and self.active(t):
            _count(counters, "blackout_dropped", len(items))
            return []
        return items


class BernoulliLoss(Stage):
    name = "loss"

    def __init__(self, p: float) -> None:
        self.p = p

    def process(self, t, items, rng, counters):
        kept = [item for item in items if rng.random() >= self.p]
        if len(kept) != len(items):
            _count(counters, "lost", len(items) - len(kept))
        return kept


class GilbertElliott(Stage):
    """Burst loss: a two-state Markov chain stepped once per message (Gilbert's model)."""

    name = "burst"

    def __init__(self, p: float, r: float) -> None:
        self.p, self.r = p, r
        self.bad = False

    def process(self, t, items, rng, counters):
        kept = []
        for item in items:
            if self.bad:
                if rng.random() < self.r:
                    self.bad = False
            elif rng.random() < self.p:
                self.bad = True
                _count(counters, "bursts")
            if self.bad:
                _count(counters, "burst_lost")
            else:
                kept.append(item)
        return kept


class Duplicate(Stage):
    name = "duplicate"

    def __init__(self, p: float) -> None:
        self.p = p

    def process(self, t, items, rng, counters):
        out = []
        for item in items:
            out.append(item)
            if rng.random() < self.p:
                out.append(item)
                _count(counters, "duplicated")
        return out


def flip_bits(payload: bytes, bits: int, rng: random.Random) -> bytes:
    """``payload`` with ``bits`` distinct bit positions inverted (all of them if it is shorter)."""
    n = len(payload) * 8
    if n == 0:
        return payload
    data = bytearray(payload)
    for pos in rng.sample(range(n), min(bits, n)):
        data[pos >> 3] ^= 1 << (pos & 7)
    return bytes(data)


class Corrupt(Stage):
    """Bit flips; the first ``skip`` bytes (a header the caller packed in front) are never touched."""

    name = "corrupt"

    def __init__(self, p: float, bits: int = 1, skip: int = 0) -> None:
        self.p, self.bits, self.skip = p, bits, skip

    def process(self, t, items, rng, counters):
        out = []
        for release, payload in items:
            body = payload[self.skip:]
            if body and rng.random() < self.p:
                _count(counters, "corrupted")
                _count(counters, "bits_flipped", min(self.bits, len(body) * 8))
                payload = payload[:self.skip] + flip_bits(body, self.bits, rng)
            out.append((release, payload))
        return out


class Replay(Stage):
    """Stale replay: keeps the messages of the last ``age`` + 1 s; may resend the one nearest ``age`` old."""

    name = "replay"

    def __init__(self, p: float, age: float) -> None:
        self.p, self.age = p, age
        self.history: deque[tuple[float, bytes]] = deque()

    def process(self, t, items, rng, counters):
        out = list(items)
        stale = None
        while len(self.history) > 1 and self.history[1][0] <= t - self.age:
            self.history.popleft()     # keep exactly one message at least `age` old at the front
        if self.history and self.history[0][0] <= t - self.age and rng.random() < self.p:
            stale = self.history[0][1]
        for _, payload in items:
            self.history.append((t, payload))
        if stale is not None:
            out.append((t, stale))
            _count(counters, "replayed")
        return out


class Delay(Stage):
    name = "delay"
    DISTRIBUTIONS = ("uniform", "normal", "pareto")

    def __init__(self, delay: float = 0.0, jitter: float = 0.0, distribution: str = "uniform") -> None:
        if distribution not in self.DISTRIBUTIONS:
            raise ValueError(f"unknown jitter distribution {distribution!r}")
        self.delay, self.jitter, self.distribution = delay, jitter, distribution
        self.last_release = float("-inf")

    def sample(self, rng: random.Random) -> float:
        """One delay in seconds (≥ 0)."""
        j = self.jitter
        if j <= 0:
            extra = 0.0
        elif self.distribution == "uniform":
            extra = rng.uniform(-j, j)
        elif self.distribution == "normal":
            extra = rng.gauss(0.0, j)
        else:   # Pareto with mean j: j·(a−1)·(X−1), X ~ Pareto(a) ≥ 1
            extra = j * (PARETO_SHAPE - 1.0) * (rng.paretovariate(PARETO_SHAPE) - 1.0)
        return max(0.0, self.delay + extra)

    def process(self, t, items, rng, counters):
        out = []
        for release, payload in items:
            d = self.sample(rng)
            when = max(release + d, self.last_release)
            self.last_release = when
            if when > release:
                _count(counters, "delayed")
                _count(counters, "delay_total_s", when - release)
            out.append((when, payload))
        return out


class Reorder(Stage):
    name = "reorder"

    def __init__(self, p: float, gap: float) -> None:
        self.p, self.gap = p, gap

    def process(self, t, items, rng, counters):
        out = []
        for release, payload in items:
            if rng.random() < self.p:
                release += self.gap
                _count(counters, "held_back")
            out.append((release, payload))
        return out


class RateLimit(Stage):
    name = "rate"

    def __init__(self, rate: float, queue: int = 1000) -> None:
        self.interval, self.queue = 1.0 / rate, queue
        self.next_free = float("-inf")

    def process(self, t, items, rng, counters):
        out = []
        for release, payload in items:
            start = max(release, self.next_free)
            if (start - release) / self.interval > self.queue:
                _count(counters, "rate_dropped")
                continue
            if start > release:
                _count(counters, "rate_delayed")
            self.next_free = start + self.interval
            out.append((start, payload))
        return out


class Pipeline:
    """A seeded chain of stages: ``feed(t, payload) -> [(release, payload), …]`` and ``counters``."""

    def __init__(self, stages: list[Stage], seed: int | str = 0) -> None:
        self.stages = stages
        self.rng = random.Random(seed)
        self.counters: dict = {"received": 0, "emitted": 0}

    def feed(self, t: float, payload: bytes) -> list[Item]:
        self.counters["received"] += 1
        items: list[Item] = [(t, payload)]
        for stage in self.stages:
            items = stage.process(t, items, self.rng, self.counters)
            if not items:
                break
        self.counters["emitted"] += len(items)
        return items

    @property
    def empty(self) -> bool:
        return not self.stages

    def describe(self) -> list[str]:
        return [stage.name for stage in self.stages]
