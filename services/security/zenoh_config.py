"""Zenoh configurations with credentials, TLS and access control, under the project's rules.

Two directions:

* **Reading** (`from_file`): a site's JSON5 (or JSON) Zenoh configuration — mode, endpoints,
  `transport/auth/usrpwd`, `transport/link/tls`, `access_control` — is loaded by Zenoh's own
  parser, then held to this project's rules: every listen/connect endpoint is an explicit
  loopback `tcp/` or `tls/` endpoint, multicast and gossip scouting are off (a file that turns
  them on is refused, not silently changed), and relative file paths in it (certificates, keys,
  the password dictionary) are taken relative to the file. Endpoints given on the command line
  replace the file's.
* **Building** (`client_config`, `router_config`, `write_config`): the configurations of a
  router and of each role's client, from a set of `credentials.Credentials`, as plain dicts
  that `write_config` saves as commented JSON5 (the examples in deploy/zenoh/ have this shape).

Zenoh 1.10 (the Python wheel) supports all of it; what was checked on this host is in
tests/services/test_security_*.py: a client without or with a wrong password is refused; under
mutual TLS a client without a certificate signed by the site CA is refused; the ACL drops an
observer's publications on operator keys. A client that sends a certificate must also set
`enable_mtls: true` — without it Zenoh does not present the certificate.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import zenoh

from ..zenoh_session import CONNECT_RETRY, EndpointError, check_loopback
from .credentials import Credentials
from .roles import ROLES, access_control, check_role_name

CONNECT_TIMEOUT_MS = 10_000
SCOUTING_OFF = {"multicast": {"enabled": False}, "gossip": {"enabled": False}}
TLS_PATH_KEYS = ("root_ca_certificate", "listen_certificate", "listen_private_key", "connect_certificate",
                 "connect_private_key")


class ZenohConfigError(ValueError):
    """A Zenoh configuration file that cannot be read or breaks the project's rules."""


def check_endpoint(endpoint: str) -> str:
    """Accept tcp/ or tls/ on a loopback address with an explicit port (nothing leaves this host)."""
    if not isinstance(endpoint, str):
        raise EndpointError(f"{endpoint!r}: an endpoint is a string")
    if endpoint.startswith("tls/"):
        try:
            check_loopback("tcp/" + endpoint[4:])
        except EndpointError as exc:
            raise EndpointError(str(exc).replace("tcp/", "tls/", 1)) from None
        return endpoint
    return check_loopback(endpoint)


def _endpoint_list(value, mode: str) -> list[str]:
    """The endpoints a node in `mode` uses: Zenoh allows a list, or a map mode -> list (its
    defaults are such a map: a router listens on tcp/[::]:7447, a peer on tcp/[::]:0)."""
    if value is None:
        return []
    if isinstance(value, dict):
        return _endpoint_list(value.get(mode), mode)
    if isinstance(value, list):
        return list(value)
    raise ZenohConfigError(f"endpoints must be a list, not {value!r}")


def _get(cfg: zenoh.Config, key: str):
    try:
        return json.loads(cfg.get_json(key))
    except Exception:   # noqa: BLE001 — zenoh raises ZError for a key it does not know
        return None


def _insert(cfg: zenoh.Config, key: str, value) -> None:
    try:
        cfg.insert_json5(key, json.dumps(value))
    except Exception as exc:   # zenoh.ZError
        raise ZenohConfigError(f"{key}: {exc}") from exc


def enforce_rules(cfg: zenoh.Config, base_dir: Path | None = None) -> zenoh.Config:
    """Loopback endpoints, scouting off, paths relative to `base_dir`; raises ZenohConfigError."""
    for key in ("scouting/multicast/enabled", "scouting/gossip/enabled"):
        if _get(cfg, key) is True:
            raise ZenohConfigError(f"{key}: scouting announces this node on the network; it must be off")
        _insert(cfg, key, False)
    for key in ("listen/endpoints", "connect/endpoints"):
        try:
            for endpoint in _endpoint_list(_get(cfg, key), mode_of(cfg)):
                check_endpoint(endpoint)
        except EndpointError as exc:
            raise ZenohConfigError(f"{key}: {exc}") from exc
    if base_dir is not None:
        for name in TLS_PATH_KEYS:
            _absolute(cfg, f"transport/link/tls/{name}", base_dir)
        _absolute(cfg, "transport/auth/usrpwd/dictionary_file", base_dir)
    return cfg


def _absolute(cfg: zenoh.Config, key: str, base_dir: Path) -> None:
    value = _get(cfg, key)
    if isinstance(value, str) and value and not Path(value).is_absolute():
        _insert(cfg, key, str((base_dir / value).resolve()))


def from_file(path: str | Path, listen: list[str] | None = None, connect: list[str] | None = None) -> zenoh.Config:
    """A Zenoh configuration from a JSON5/JSON file; `listen`/`connect`, when given, replace the file's."""
    path = Path(path)
    if not path.is_file():
        raise ZenohConfigError(f"{path}: no such file")
    try:
        cfg = zenoh.Config.from_file(str(path))
    except Exception as exc:   # zenoh.ZError: syntax or an unknown key
        raise ZenohConfigError(f"{path}: {exc}") from exc
    if listen:
        _insert(cfg, "listen/endpoints", list(listen))
    if connect:
        _insert(cfg, "connect/endpoints", list(connect))
    try:
        return enforce_rules(cfg, path.resolve().parent)
    except ZenohConfigError as exc:
        raise ZenohConfigError(f"{path}: {exc}") from exc


def open_from_file(path: str | Path, listen: list[str] | None = None,
                   connect: list[str] | None = None) -> zenoh.Session:
    """Open a session from a configuration file (the caller must `close()` it)."""
    return zenoh.open(from_file(path, listen, connect))


def mode_of(cfg: zenoh.Config) -> str:
    return _get(cfg, "mode") or "peer"


# ----- building configurations for a router and its clients ------------------------
def tls_files(creds: Credentials, name: str, listen: bool) -> dict:
    """`transport/link/tls` for the router (`listen`) or a role's client: the site CA, its own
    certificate and key, mutual TLS on, the server's name checked on connect."""
    tls = {"root_ca_certificate": str(creds.ca), "enable_mtls": True}
    side = "listen" if listen else "connect"
    tls[f"{side}_certificate"] = str(creds.certificate(name))
    tls[f"{side}_private_key"] = str(creds.private_key(name))
    if not listen:
        tls["verify_name_on_connect"] = True
    return tls


def client_config(role: str, creds: Credentials, connect: list[str], usrpwd: bool = True) -> dict:
    """A role's (or a named operator's) client of the router: its user/password and, for tls/ endpoints, its
    certificate."""
    role = check_role_name(role)
    cfg: dict = {"mode": "client", "connect": {"endpoints": [check_endpoint(e) for e in connect],
                                               "timeout_ms": CONNECT_TIMEOUT_MS, "retry": CONNECT_RETRY},
                 "scouting": SCOUTING_OFF, "transport": {}}
    if usrpwd:
        cfg["transport"]["auth"] = {"usrpwd": {"user": role, "password": creds.users[role]}}
    if any(e.startswith("tls/") for e in connect):
        cfg["transport"]["link"] = {"tls": tls_files(creds, role, listen=False)}
    return cfg


def router_config(creds: Credentials, listen: list[str], usrpwd: bool = True, acl: bool = True,
                  roles=ROLES) -> dict:
    """The router: the password dictionary, mutual TLS on tls/ endpoints, default-deny ACL per role."""
    tls = any(e.startswith("tls/") for e in listen)
    cfg: dict = {"mode": "router", "listen": {"endpoints": [check_endpoint(e) for e in listen]},
                 "connect": {"endpoints": []}, "scouting": SCOUTING_OFF, "transport": {}}
    if usrpwd:
        cfg["transport"]["auth"] = {"usrpwd": {"dictionary_file": str(creds.dictionary)}}
    if tls:
        cfg["transport"]["link"] = {"tls": tls_files(creds, "router", listen=True)}
    if acl:
        cfg["access_control"] = access_control(roles, tls=tls, usrpwd=usrpwd, operators=creds.operators or None)
    return cfg


def write_config(path: str | Path, cfg: dict, header: str = "") -> Path:
    """Save `cfg` as JSON5 (JSON with a `//` comment header), readable by `from_file` and zenohd."""
    path = Path(path)
    comment = "".join(f"// {line}\n" if line else "//\n" for line in header.splitlines())
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)   # it may carry a password
    with os.fdopen(fd, "w") as out:
        out.write(comment + json.dumps(cfg, indent=2) + "\n")
    os.chmod(path, 0o600)   # an existing file keeps its mode on O_CREAT
    return path


# ----- what the service commands call (`--zenoh-config FILE`) ----------------------
def add_argument(parser) -> None:
    """`--zenoh-config FILE` on a service command."""
    parser.add_argument("--zenoh-config", metavar="FILE",
                        help="Zenoh JSON5 configuration: mode, endpoints, credentials, TLS (deploy/zenoh/*.json5); "
                             "--zenoh-listen/--zenoh-connect replace its endpoints; loopback only, scouting off")


def check_session_args(config_file: str | None, listen: list[str] | None, connect: list[str] | None) -> None:
    """Validate before anything opens: the file (if any) and the endpoints; raises ValueError."""
    if config_file:
        from_file(config_file, listen, connect)
    else:
        from ..zenoh_session import config
        config(listen, connect)


def describe(config_file: str | None, listen: list[str] | None, connect: list[str] | None) -> str:
    """How a service's session reaches the others, for its start line: its endpoints and/or its configuration
    file (whose own endpoints apply where none are given)."""
    parts = [f"listen {e}" for e in listen or []] + [f"connect {e}" for e in connect or []]
    if config_file:
        parts.append(f"config {config_file}")
    return " ".join(parts) or "default endpoints"


def open_configured(config_file: str | None, listen: list[str] | None, connect: list[str] | None) -> zenoh.Session:
    """The session a service opens: from `config_file` when given, else the plain loopback peer."""
    if config_file:
        return open_from_file(config_file, listen, connect)
    from ..zenoh_session import open_session
    return open_session(listen, connect)
