"""A Zenoh sample as a subscriber's callback sees it (its key and its payload's bytes), for tests that
call the callbacks directly, without a session."""
from __future__ import annotations


class Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class Sample:
    def __init__(self, data: bytes, key: str = "") -> None:
        self.key_expr, self.payload = key, Payload(data)
