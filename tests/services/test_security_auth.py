"""Authentication, access control and mutual TLS with real Zenoh sessions on loopback.

A router session (the configuration `sharedctl router` runs, built by
services/security/zenoh_config.py) with usrpwd, default-deny ACL and, in the mTLS tests, a
`tls/` endpoint; the clients are the per-role configurations."""
from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zenoh

from sharedctl.protocol import keys
from sharedctl.services.security import credentials
from sharedctl.services.security.signing import TrustList
from sharedctl.services.security.zenoh_config import client_config, from_file, router_config
from sharedctl.services.zenoh_session import free_loopback_port

from .processes import reap, wait_for

pytestmark = pytest.mark.processes

REFUSE_TIMEOUT_MS = 1000     # how long a refused client keeps trying before zenoh.open raises
CONNECT_TIMEOUT_MS = 8000    # a client that should get in (generous: the host is shared)
DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
ROBOT = "robot1"


def _open(cfg: dict) -> zenoh.Session:
    return zenoh.open(zenoh.Config.from_json5(json.dumps(cfg)))


def _client(role, creds, endpoint, **changes) -> dict:
    cfg = client_config(role, creds, [endpoint])
    cfg["connect"]["timeout_ms"] = CONNECT_TIMEOUT_MS
    for path, value in changes.items():       # "transport/auth/usrpwd/password" -> value (None deletes)
        *parents, leaf = path.split("/")
        node = cfg
        for p in parents:
            node = node.setdefault(p, {})
        if value is None:
            node.pop(leaf, None)
        else:
            node[leaf] = value
    return cfg


def _refused(cfg: dict) -> bool:
    cfg["connect"]["timeout_ms"] = REFUSE_TIMEOUT_MS
    try:
        session = _open(cfg)
    except zenoh.ZError:
        return True
    session.close()
    return False


@pytest.fixture(scope="module")
def creds(tmp_path_factory):
    return credentials.generate(tmp_path_factory.mktemp("creds"))


@pytest.fixture(scope="module")
def tcp_router(creds):
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    router = _open(router_config(creds, [endpoint]))
    yield endpoint
    router.close()


@pytest.fixture(scope="module")
def tls_router(creds):
    endpoint = f"tls/127.0.0.1:{free_loopback_port()}"
    router = _open(router_config(creds, [endpoint]))
    yield endpoint
    router.close()


# ----- user/password --------------------------------------------------------------
def test_client_with_its_password_connects(creds, tcp_router):
    session = _open(_client("observer", creds, tcp_router))
    try:
        assert len(session.info.routers_zid()) == 1
    finally:
        session.close()


def test_client_without_credentials_is_refused(creds, tcp_router):
    assert _refused(_client("operator", creds, tcp_router, **{"transport/auth": None}))


def test_client_with_a_wrong_password_is_refused(creds, tcp_router):
    assert _refused(_client("operator", creds, tcp_router, **{"transport/auth/usrpwd/password": "not-the-password"}))


def test_a_role_name_with_another_roles_password_is_refused(creds, tcp_router):
    assert _refused(_client("operator", creds, tcp_router,
                            **{"transport/auth/usrpwd/password": creds.users["observer"]}))


# ----- access control ----------------------------------------------------------
class Inbox:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.payloads: list[bytes] = []

    def __call__(self, sample) -> None:
        with self.lock:
            self.payloads.append(sample.payload.to_bytes())

    def count(self, payload: bytes) -> int:
        with self.lock:
            return self.payloads.count(payload)


def _publish_both(creds, endpoint, key, writer_role, intruder_role, listener_role, n=20, expect_writer=True):
    """`writer` and `intruder` each put n samples on `key`; what does `listener` receive?"""
    sessions = [_open(_client(r, creds, endpoint)) for r in (listener_role, writer_role, intruder_role)]
    listener, writer, intruder = sessions
    inbox = Inbox()
    try:
        sub = listener.declare_subscriber(key, inbox)
        probe = writer.declare_publisher(key)
        # the subscription has reached the router once the writer's publisher matches it
        wait_for(lambda: probe.matching_status.matching, 5.0, "the subscription to reach the router")
        for _ in range(n):
            intruder.put(key, b"intruder")
            writer.put(key, b"writer")
            time.sleep(0.005)
        if expect_writer:
            wait_for(lambda: inbox.count(b"writer") == n, 5.0, "the writer's samples")
            time.sleep(0.2)     # anything else in flight
        else:
            time.sleep(1.0)     # long enough for n samples to arrive, were they delivered
        probe.undeclare()
        sub.undeclare()
        return inbox.count(b"writer"), inbox.count(b"intruder")
    finally:
        for s in sessions:
            s.close()


def test_observer_cannot_publish_operator_commands(creds, tcp_router):
    got_operator, got_observer = _publish_both(creds, tcp_router, keys.operator_cmd_key(ROBOT),
                                               writer_role="operator", intruder_role="observer",
                                               listener_role="controller")
    assert got_operator == 20
    assert got_observer == 0


def test_an_operator_never_receives_another_operators_commands(creds, tcp_router):
    """Operators share the role's credentials; hiding the command stream hides the session ids."""
    key = keys.operator_cmd_key(ROBOT)
    got_by_operator = _publish_both(creds, tcp_router, key, writer_role="operator", intruder_role="operator",
                                    listener_role="operator", expect_writer=False)
    got_by_observer = _publish_both(creds, tcp_router, key, writer_role="operator", intruder_role="operator",
                                    listener_role="observer")
    assert got_by_operator == (0, 0)
    assert got_by_observer == (20, 20)


def test_operator_cannot_publish_robot_state(creds, tcp_router):
    got_controller, got_operator = _publish_both(creds, tcp_router, keys.state_key(ROBOT),
                                                 writer_role="controller", intruder_role="operator",
                                                 listener_role="observer")
    assert got_controller == 20
    assert got_operator == 0


def test_controller_cannot_forge_ground_truth(creds, tcp_router):
    got_robot, got_controller = _publish_both(creds, tcp_router, keys.truth_key(ROBOT),
                                              writer_role="robot", intruder_role="controller",
                                              listener_role="observer")
    assert got_robot == 20
    assert got_controller == 0


# ----- named operators, each with its robots ----------------------------------------------
@pytest.fixture(scope="module")
def named(tmp_path_factory):
    """A site whose operators have names: alice may command robot1, bob robot2."""
    site = credentials.generate(tmp_path_factory.mktemp("named"), operators={"alice": (ROBOT,), "bob": ("robot2",)})
    endpoint = f"tls/127.0.0.1:{free_loopback_port()}"
    router = _open(router_config(site, [endpoint]))
    yield site, endpoint
    router.close()


def test_an_operator_reaches_only_its_own_robots_at_the_router(named):
    """Before, one operator credential and the `*` robot chunk let any operator command every robot on the router."""
    site, endpoint = named
    assert _publish_both(site, endpoint, keys.operator_cmd_key(ROBOT), writer_role="alice", intruder_role="bob",
                         listener_role="controller", n=10) == (10, 0)
    assert _publish_both(site, endpoint, keys.operator_cmd_key("robot2"), writer_role="bob", intruder_role="alice",
                         listener_role="controller", n=10) == (10, 0)


def test_an_operator_name_with_another_operators_password_is_refused(named):
    site, endpoint = named
    assert _refused(_client("alice", site, endpoint, **{"transport/auth/usrpwd/password": site.users["bob"]}))


def test_an_operators_password_with_another_operators_certificate_commands_no_robot(named):
    """TLS checks the certificate's CA, usrpwd the password: the two of different operators get in, but a subject
    needs the user name *and* the common name, so such a connection matches none and the router drops it all."""
    site, endpoint = named
    mixed = _client("alice", site, endpoint, **{"transport/link/tls/connect_certificate": str(site.certificate("bob")),
                                                "transport/link/tls/connect_private_key": str(site.private_key("bob"))})
    sessions = [_open(_client("controller", site, endpoint)), _open(mixed), _open(_client("alice", site, endpoint))]
    listener, intruder, alice = sessions
    inbox = Inbox()
    try:
        subs = [listener.declare_subscriber(keys.operator_cmd_key(robot), inbox) for robot in (ROBOT, "robot2")]
        probe = alice.declare_publisher(keys.operator_cmd_key(ROBOT))
        wait_for(lambda: probe.matching_status.matching, 5.0, "the subscription to reach the router")
        for _ in range(10):
            for robot in (ROBOT, "robot2"):
                intruder.put(keys.operator_cmd_key(robot), b"intruder")
            alice.put(keys.operator_cmd_key(ROBOT), b"alice")
            time.sleep(0.005)
        wait_for(lambda: inbox.count(b"alice") == 10, 5.0, "alice's samples")
        time.sleep(0.3)
        assert inbox.count(b"intruder") == 0
        for entity in (probe, *subs):
            entity.undeclare()
    finally:
        for session in sessions:
            session.close()


# ----- mutual TLS ---------------------------------------------------------------
def test_mtls_client_with_its_certificate_connects(creds, tls_router):
    session = _open(_client("operator", creds, tls_router))
    try:
        assert len(session.info.routers_zid()) == 1
    finally:
        session.close()


def test_mtls_refuses_a_client_without_a_certificate(creds, tls_router):
    cfg = _client("operator", creds, tls_router, **{"transport/link/tls/connect_certificate": None,
                                                     "transport/link/tls/connect_private_key": None,
                                                     "transport/link/tls/enable_mtls": None})
    assert "usrpwd" in cfg["transport"]["auth"]       # the password alone is not enough
    assert _refused(cfg)


def test_mtls_refuses_a_certificate_from_another_ca(creds, tls_router, tmp_path):
    other = credentials.generate(tmp_path / "other", roles=("operator",))
    cfg = _client("operator", creds, tls_router, **{
        "transport/link/tls/connect_certificate": str(other.certificate("operator")),
        "transport/link/tls/connect_private_key": str(other.private_key("operator"))})
    assert _refused(cfg)


def test_acl_under_mtls_matches_the_certificate_common_name(creds, tls_router):
    got_operator, got_observer = _publish_both(creds, tls_router, keys.operator_cmd_key(ROBOT),
                                               writer_role="operator", intruder_role="observer",
                                               listener_role="controller", n=10)
    assert (got_operator, got_observer) == (10, 0)


# ----- the router command and the site script -------------------------------------------
def test_make_credentials_writes_a_site_that_sharedctl_router_enforces(tmp_path):
    """deploy/make-credentials.sh -> DIR/router.json5 runs as `sharedctl router --config`; DIR/operator.json5
    (paths relative to the file) gets in; the same without its certificate and password does not."""
    endpoint = f"tls/127.0.0.1:{free_loopback_port()}"
    site = tmp_path / "site"
    env = dict(os.environ, SHAREDCTL_ROUTER_ENDPOINT=endpoint,
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    made = subprocess.run(["sh", str(DEPLOY / "make-credentials.sh"), str(site), "--days", "2"], env=env,
                          capture_output=True, text=True, timeout=60)
    assert made.returncode == 0, made.stderr
    assert sorted(p.name for p in site.glob("*.json5")) == ["controller.json5", "observer.json5", "operator.json5",
                                                          "robot.json5", "router.json5"]
    # the operator's signing key is its own; the controller's list of trusted operators is public
    assert stat.S_IMODE((site / "operator.signing-key.pem").stat().st_mode) == 0o600
    assert stat.S_IMODE((site / "operators.toml").stat().st_mode) == 0o644
    assert set(TrustList.from_file(site / "operators.toml").operators) == {"operator"}
    # the router module alone (`sharedctl router` runs the same `run`, after importing every sub-command)
    proc = subprocess.Popen([sys.executable, "-m", "sharedctl.services.security.router_command", "--config",
                             str(site / "router.json5"), "--duration", "60"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        banner = proc.stdout.readline()
        assert "usrpwd on" in banner and "mTLS on" in banner and "ACL on" in banner, banner
        session = zenoh.open(from_file(site / "operator.json5"))
        assert len(session.info.routers_zid()) == 1
        session.close()
        anonymous = {"mode": "client", "connect": {"endpoints": [endpoint]},
                     "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
                     "transport": {"link": {"tls": {"root_ca_certificate": str(site / "ca.pem")}}}}
        assert _refused(anonymous)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
    finally:
        reap([proc])
        proc.stdout.close()


# ----- the router command -------------------------------------------------------
