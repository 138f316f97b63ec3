"""Credentials for a sharedctl site: a private CA, TLS certificates and user/password pairs.

One call, `generate(directory)`, writes everything a router and its clients need:

    ca.pem                  the site's CA certificate (root_ca_certificate of every node)
    ca-key.pem              the CA's private key (keep it off the robot; needed only to issue more)
    router.pem / -key.pem   the router's server certificate: CN "router", SAN localhost and 127.0.0.1
                            (listen_certificate / listen_private_key)
    ROLE.pem / -key.pem     one client certificate per role, CN = the role (connect_certificate /
                            connect_private_key; the ACL matches `cert_common_names` on it under mTLS)
    passwords.txt           the router's usrpwd dictionary_file: one `user:password` line per role
    ROLE.password           that role's password alone (what its own config carries)
    NAME.signing-key.pem    each operator's Ed25519 key for signing its commands and lease requests
                            (`sharedctl console --signing-key`; services/security/signing.py)
    operators.toml          the operators a controller trusts: each one's public key and robots
                            (`sharedctl controller --operators`)

Operators are named: `operators={"alice": ("robot1",), "bob": ("*",)}` writes a user, a
certificate (CN = the name), a password and a signing key per operator instead of the single
`operator` role's, and the router's ACL (roles.py) gives each one the keys of its robots only.
Without `operators` the single operator is named `operator` and may command every robot.

Keys are ECDSA P-256 in PKCS#8 PEM, mode 0600; certificates are X.509 v3 with the extensions
rustls (Zenoh's TLS) insists on: the CA has basicConstraints CA:TRUE and keyCertSign, leaves are
CA:FALSE with digitalSignature and a serverAuth/clientAuth extended key usage. Passwords are 32
characters from `secrets.token_urlsafe`. `deploy/make-credentials.sh` runs this for a site; the
secure demo and the tests run it in a temporary directory.
"""
from __future__ import annotations

import datetime
import ipaddress
import os
import secrets
from dataclasses import dataclass, field
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from .roles import ROLES, principals
from .signing import trust_file_text, write_private_key

ROUTER_NAME = "router"
DEFAULT_HOSTS = ("localhost", "127.0.0.1")
DEFAULT_DAYS = 365


class CredentialsError(ValueError):
    """A credentials directory that cannot be written or read."""


@dataclass(frozen=True)
class Credentials:
    """Paths (and passwords) of one generated set; `directory` holds them all."""

    directory: Path
    users: dict[str, str] = field(default_factory=dict)      # user (a role, or an operator's name) -> password
    operators: dict[str, tuple[str, ...]] = field(default_factory=dict)   # operator name -> robots it may command

    @property
    def ca(self) -> Path:
        return self.directory / "ca.pem"

    @property
    def dictionary(self) -> Path:
        return self.directory / "passwords.txt"

    def certificate(self, name: str) -> Path:
        return self.directory / f"{name}.pem"

    def private_key(self, name: str) -> Path:
        return self.directory / f"{name}-key.pem"

    def signing_key(self, operator: str) -> Path:
        return self.directory / f"{operator}.signing-key.pem"

    @property
    def trust_file(self) -> Path:
        return self.directory / "operators.toml"


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "sharedctl site"),
                      x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _write_key(path: Path, key: ec.EllipticCurvePrivateKey) -> None:
    data = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())
    _write_secret(path, data)


def _write_secret(path: Path, data: bytes) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(data)


def _write_cert(path: Path, cert: x509.Certificate) -> None:
    path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def _builder(subject: str, issuer: x509.Name, public_key, days: int) -> x509.CertificateBuilder:
    now = datetime.datetime.now(datetime.timezone.utc)
    return (x509.CertificateBuilder().subject_name(_name(subject)).issuer_name(issuer).public_key(public_key)
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=days)))


def _leaf(common_name: str, ca_cert: x509.Certificate, ca_key, days: int, server_hosts=()) -> tuple:
    key = ec.generate_private_key(ec.SECP256R1())
    builder = (_builder(common_name, ca_cert.subject, key.public_key(), days)
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.KeyUsage(True, False, False, False, False, False, False, False, False),
                              critical=True)
               .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False))
    if server_hosts:
        sans: list[x509.GeneralName] = []
        for host in server_hosts:
            try:
                sans.append(x509.IPAddress(ipaddress.ip_address(host)))
            except ValueError:
                sans.append(x509.DNSName(host))
        builder = (builder.add_extension(x509.SubjectAlternativeName(sans), critical=False)
                   .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                                         ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False))
    else:
        builder = builder.add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
    return builder.sign(ca_key, hashes.SHA256()), key


def generate(directory: str | Path, roles=ROLES, hosts=DEFAULT_HOSTS, days: int = DEFAULT_DAYS,
             operators: dict | None = None) -> Credentials:
    """Write a fresh CA, the router's certificate, one client certificate and password per role (per named
    operator for the operator role), and each operator's signing key and the operators file."""
    directory = Path(directory)
    named = principals(roles, operators)
    operators = {name: robots for name, (role, robots) in named.items() if role == "operator"}
    if days <= 0:
        raise CredentialsError("days must be positive")
    try:
        directory.mkdir(parents=True, exist_ok=True)
        ca_key = ec.generate_private_key(ec.SECP256R1())
        ca_cert = (_builder("sharedctl site CA", _name("sharedctl site CA"), ca_key.public_key(), days)
                   .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
                   .add_extension(x509.KeyUsage(False, False, False, False, False, True, True, False, False),
                                  critical=True)
                   .add_extension(x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), critical=False)
                   .sign(ca_key, hashes.SHA256()))
        creds = Credentials(directory, {name: secrets.token_urlsafe(24) for name in named}, operators)
        _write_cert(creds.ca, ca_cert)
        _write_key(directory / "ca-key.pem", ca_key)
        cert, key = _leaf(ROUTER_NAME, ca_cert, ca_key, days, server_hosts=hosts)
        _write_cert(creds.certificate(ROUTER_NAME), cert)
        _write_key(creds.private_key(ROUTER_NAME), key)
        for name in named:
            cert, key = _leaf(name, ca_cert, ca_key, days)
            _write_cert(creds.certificate(name), cert)
            _write_key(creds.private_key(name), key)
            _write_secret(directory / f"{name}.password", creds.users[name].encode() + b"\n")
        _write_secret(creds.dictionary, "".join(f"{u}:{p}\n" for u, p in creds.users.items()).encode())
        signing = {name: Ed25519PrivateKey.generate() for name in operators}
        for name, key in signing.items():
            write_private_key(creds.signing_key(name), key)
        if signing:
            creds.trust_file.write_text(trust_file_text({n: (k, operators[n]) for n, k in signing.items()}))
    except OSError as exc:
        raise CredentialsError(f"cannot write credentials in {directory}: {exc}") from exc
    return creds


def load(directory: str | Path, roles=ROLES, operators: dict | None = None) -> Credentials:
    """The credentials `generate` wrote in `directory` (passwords read from NAME.password)."""
    directory = Path(directory)
    named = principals(roles, operators)
    users = {}
    for role in named:
        path = directory / f"{role}.password"
        try:
            users[role] = path.read_text().strip()
        except OSError as exc:
            raise CredentialsError(f"cannot read {path}: {exc}") from exc
    return Credentials(directory, users, {n: robots for n, (role, robots) in named.items() if role == "operator"})
