"""Operator commands from Zenoh to the operator policy: a channel the loop polls, a bounded queue, arrival order.

No Python callback thread runs for operator commands. Zenoh holds their samples in a FIFO channel
(`channel()`); the loop thread takes them (`take`) between CAN frames and before each tick, and
hands them to the policy in arrival order (`apply`). A callback thread would need the GIL, and one
preempted while holding it (on a busy CPU, behind a real-time thread) stalls the real-time loop
behind it. The price: a command is stamped when taken, at most one receive slice of the loop
(0.5 ms) after it arrived — well inside the policy's age limits (replay_guard.py).

Only the loop takes and applies (lease queries wait in their own channel, zenoh_links.py), under the
daemon's lock. Each `apply` judges at most `BUDGET` payloads, so a flood costs the loop a bounded
time per call. A full queue refuses and counts (`command_queue_full`); a full channel holds the
sender back inside Zenoh (nothing is dropped unseen). An operator's 50 Hz never fills either: the
loop judges up to `BUDGET` every 0.5 ms.
"""
from __future__ import annotations

import time
from collections import deque

import zenoh

MAX_PENDING = 1000        # payloads taken from the channel and not yet judged
CHANNEL_CAPACITY = 1000   # samples Zenoh holds for the loop
BUDGET = 16               # payloads judged per `apply` (≈ 0.5 ms of decoding and judging at most)


def channel():
    """The handler to declare the operator-command subscriber with."""
    return zenoh.handlers.FifoChannel(CHANNEL_CAPACITY)


def attachment_bytes(sample) -> bytes | None:
    """A sample's (or a query's) Zenoh attachment as bytes; None without one or if it cannot be read."""
    try:
        attachment = sample.attachment
        return None if attachment is None else attachment.to_bytes()
    except Exception:  # noqa: BLE001 — an unreadable attachment is none: a signed stream refuses it
        return None


class CommandIntake:
    """`subscriber.try_recv()` → (payload, monotonic, wall) queue → `policy.offer`, in arrival order."""

    def __init__(self, subscriber, policy, clock=time.monotonic, wall_clock=time.time) -> None:
        self.subscriber = subscriber
        self.policy = policy
        self.clock, self.wall_clock = clock, wall_clock
        self.pending: deque = deque()
        self.overflowed = 0                      # payloads refused because the queue was full
        self.taken = 0                           # samples taken from the channel so far

    def take(self) -> None:
        """Every sample waiting in the channel into the queue."""
        for _ in range(CHANNEL_CAPACITY):
            sample = self.subscriber.try_recv()
            if sample is None:
                return
            self.taken += 1
            self.queue(sample)

    def queue(self, sample) -> None:
        """One sample's payload and attachment with the times it was taken (an unreadable payload queues as empty
        bytes, an unreadable attachment as none: the policy refuses and counts them)."""
        try:
            payload = sample.payload.to_bytes()
        except Exception:  # noqa: BLE001 — an unreadable payload is queued as empty bytes, never raised in the loop
            payload = b""
        attachment = attachment_bytes(sample)
        if len(self.pending) >= MAX_PENDING:
            self.overflowed += 1
            return
        self.pending.append((payload, self.clock(), self.wall_clock(), attachment))

    def apply(self) -> None:
        """Take what waits in the channel, then hand the oldest `BUDGET` queued payloads to the policy in
        order (the rest wait for the next call: a flood costs the loop a bounded time per call)."""
        self.take()
        pending = self.pending
        for _ in range(min(BUDGET, len(pending))):
            payload, now, wall, attachment = pending.popleft()
            self.policy.offer(payload, now, wall, attachment)
        if self.overflowed:
            overflowed, self.overflowed = self.overflowed, 0
            self.policy.rejections["command_queue_full"] += overflowed
