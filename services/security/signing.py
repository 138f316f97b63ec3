"""Operator identity: Ed25519 signing keys, the controller's list of trusted operators, verification.

The wire format (the attachment and the bytes it covers) is protocol/signature.py; this module
holds the keys.

* **Console side** — `Signer(operator_id, private_key)`: `attachment(key_expr, payload)` signs
  what is about to be put or queried. The key is a PKCS#8 PEM Ed25519 private key
  (`NAME.signing-key.pem`, mode 0600, written by `sharedctl credentials`).
* **Controller side** — `TrustList` (the operators file, TOML):

      [operators.alice]
      public_key = "<base64 of the 32-byte Ed25519 public key>"
      robots = ["robot1"]             # the robots alice may command; ["*"] for every robot

  `verifier(key_expr, robot_id)` returns the function the controller calls on every operator
  command and lease query: `(payload, attachment) -> (signer, None)` when the attachment holds a
  valid signature by an operator the file trusts for this robot, else `(None, reason)` with
  reason one of `unsigned` (no attachment), `bad_attachment` (not a signature attachment),
  `unknown_operator`, `not_permitted` (this robot is not in the operator's list) and
  `bad_signature`. The cheap checks come first: an unknown or unauthorised signer costs no
  signature verification.

A signature binds the message to an operator and to the key expression (one robot's command or
lease key), never to a time: freshness is the replay guard's (services/controller/replay_guard.py).
"""
from __future__ import annotations

import base64
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.signature import decode_attachment, encode_attachment, signed_bytes
from sharedctl.protocol.wire_types import check_token

ANY_ROBOT = "*"
REASONS = ("unsigned", "bad_attachment", "unknown_operator", "not_permitted", "bad_signature")


class SigningError(ValueError):
    """A signing key or an operators file that cannot be read or is not valid."""


# ----- keys ------------------------------------------------------------------------
def write_private_key(path: str | Path, key: Ed25519PrivateKey) -> Path:
    """PKCS#8 PEM, mode 0600."""
    path = Path(path)
    data = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(data)
    os.chmod(path, 0o600)
    return path


def read_private_key(path: str | Path) -> Ed25519PrivateKey:
    try:
        key = serialization.load_pem_private_key(Path(path).read_bytes(), password=None)
    except (OSError, ValueError, TypeError) as exc:
        raise SigningError(f"{path}: not a readable PEM private key ({exc})") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise SigningError(f"{path}: an operator signing key is Ed25519, not {type(key).__name__}")
    return key


def public_key_text(key: Ed25519PrivateKey | Ed25519PublicKey) -> str:
    """The raw 32-byte public key, base64 (what the operators file holds)."""
    public = key.public_key() if isinstance(key, Ed25519PrivateKey) else key
    return base64.b64encode(public.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)).decode()


class Signer:
    """Signs one operator's messages."""

    def __init__(self, operator_id: str, key: Ed25519PrivateKey) -> None:
        try:
            self.operator_id = check_token(operator_id, "operator id")
        except ProtocolError as exc:
            raise SigningError(str(exc)) from None
        self.key = key

    @classmethod
    def from_file(cls, path: str | Path, operator_id: str) -> "Signer":
        return cls(operator_id, read_private_key(path))

    def attachment(self, key_expr: str, payload: bytes) -> bytes:
        """The attachment to send with `payload` on `key_expr`."""
        return encode_attachment(self.operator_id, self.key.sign(signed_bytes(key_expr, payload)))


# ----- the controller's list ----------------------------------------------------------
@dataclass(frozen=True)
class Trusted:
    """One operator the controller trusts: its public key and the robots it may command."""

    name: str
    public_key: Ed25519PublicKey
    robots: tuple[str, ...]

    def permits(self, robot_id: str) -> bool:
        return ANY_ROBOT in self.robots or robot_id in self.robots


class TrustList:
    """The operators a controller accepts commands and lease requests from."""

    def __init__(self, operators: dict[str, Trusted]) -> None:
        if not operators:
            raise SigningError("an operators file must trust at least one operator")
        self.operators = dict(operators)

    @classmethod
    def from_file(cls, path: str | Path) -> "TrustList":
        try:
            text = Path(path).read_text()
        except OSError as exc:
            raise SigningError(f"cannot read the operators file {path}: {exc}") from None
        try:
            return cls.from_text(text)
        except SigningError as exc:
            raise SigningError(f"{path}: {exc}") from None

    @classmethod
    def from_text(cls, text: str) -> "TrustList":
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise SigningError(f"not TOML: {exc}") from None
        unknown = set(data) - {"operators"}
        if unknown:
            raise SigningError(f"unknown table(s) {sorted(unknown)} (only [operators.NAME])")
        table = data.get("operators")
        if not isinstance(table, dict):
            raise SigningError("no [operators.NAME] table")
        return cls({name: _trusted(name, entry) for name, entry in table.items()})

    def verifier(self, key_expr: str, robot_id: str):
        """`(payload, attachment) -> (signer, None) | (None, reason)` for messages on `key_expr` of `robot_id`."""
        operators = self.operators

        def verify(payload: bytes, attachment: bytes | None) -> tuple[str | None, str | None]:
            if not attachment:
                return None, "unsigned"
            try:
                signature = decode_attachment(attachment)
            except ProtocolError:
                return None, "bad_attachment"
            trusted = operators.get(signature.signer)
            if trusted is None:
                return None, "unknown_operator"
            if not trusted.permits(robot_id):
                return None, "not_permitted"
            try:
                trusted.public_key.verify(signature.value, signed_bytes(key_expr, payload))
            except InvalidSignature:
                return None, "bad_signature"
            return signature.signer, None

        return verify


def _trusted(name: str, entry) -> Trusted:
    try:
        check_token(name, "operator name")
    except ProtocolError as exc:
        raise SigningError(str(exc)) from None
    if not isinstance(entry, dict) or set(entry) - {"public_key", "robots"}:
        raise SigningError(f"operators.{name}: only public_key and robots")
    try:
        raw = base64.b64decode(str(entry.get("public_key", "")), validate=True)
        public = Ed25519PublicKey.from_public_bytes(raw)
    except ValueError:
        raise SigningError(f"operators.{name}.public_key: not a base64 32-byte Ed25519 public key") from None
    robots = entry.get("robots")
    if not isinstance(robots, list) or not robots:
        raise SigningError(f"operators.{name}.robots: a non-empty list of robot ids (or [\"*\"])")
    for robot in robots:
        if robot != ANY_ROBOT:
            try:
                check_token(robot, f"operators.{name}.robots")
            except ProtocolError as exc:
                raise SigningError(str(exc)) from None
    return Trusted(name, public, tuple(robots))


def trust_file_text(operators: dict[str, tuple[Ed25519PrivateKey | Ed25519PublicKey, tuple[str, ...]]]) -> str:
    """The operators file for {name: (key, robots)} (what `sharedctl credentials` writes)."""
    lines = ["# Operators this controller accepts (sharedctl controller --operators FILE): each one's Ed25519",
             "# public key and the robots it may command. Written by `sharedctl credentials`.", ""]
    for name, (key, robots) in operators.items():
        check_token(name, "operator name")
        robots_text = ", ".join(f'"{r}"' for r in robots)
        lines += [f"[operators.{name}]", f'public_key = "{public_key_text(key)}"', f"robots = [{robots_text}]", ""]
    return "\n".join(lines)
