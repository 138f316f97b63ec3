"""A Zenoh sample as a subscriber's callback sees it (its key, its payload's bytes and its attachment), for tests
that call the callbacks directly, without a session."""
from __future__ import annotations


class Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class Sample:
    def __init__(self, data: bytes, key: str = "", attachment: bytes | None = None) -> None:
        self.key_expr, self.payload = key, Payload(data)
        self.attachment = None if attachment is None else Payload(attachment)
