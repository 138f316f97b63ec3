"""The secure side of `sharedctl demo --secure`: throw-away credentials, a router, per-role clients.

The demo (`services/demo/command.py`) calls this module in a few places; without ``--secure`` every method is inert
and the demo is the plain peer-to-peer one.

With ``--secure``:

* a temporary directory gets a fresh site CA, the router's and each role's certificate, and
  passwords (services/security/credentials.py), plus `router.json5` and `ROLE.json5`
  (services/security/zenoh_config.py); it is removed when the demo ends;
* a `sharedctl router --config router.json5` child listens on ``--zenoh-listen`` (default a free
  `tls/127.0.0.1:PORT`: mutual TLS; a `tcp/` endpoint gives usrpwd without TLS) with
  user/password authentication and the default-deny ACL of services/security/roles.py;
* robot, controller and console run as clients of the router, each with its own role's
  configuration (`--zenoh-config`), and the demo measures through an `observer` client:

      router      listens  tls/127.0.0.1:S   (usrpwd + mTLS + ACL)
      robot       client   role robot        (GroundTruth)
      controller  client   role controller   (RobotState, Events; lease queryable)
      console     client   role operator     (OperatorCommand, lease queries)
      demo        client   role observer     (subscribes only)

Operators are named and sign (services/security/signing.py): the credentials name the console's
operator (`operator`) and, when an estop fault is injected, the fault's estop button, each allowed
this robot only at the router; the controller runs with `--operators` (their public keys) and the
console with `--signing-key`, so every command and lease request that drives is signed, and the
lease is held by a verified identity.

With ``--fault``: every fault. The Zenoh link faults (``operator.*``/``telemetry.*`` impairments)
need the relay in the only path between console and controller: the console then connects to a
router of its own (`console_endpoint`, the same credentials and rules), and the relay is a client
of both — of the console's router as the controller role, of the site router as the console's
operator (`relay_args`) — so every message still passes two authenticating, access-controlled
routers, and the operator's signatures pass the relay untouched. Faults that publish
operator commands (``operator.estop_at``, ``flood_at``, ``evict_at``) do so on a session of the
operator role (`operator_session`); the estop signed by its own operator (`signer`), the flood and
the junk sessions of the eviction unsigned (an intruder with the router's credentials but no
operator's key); ``router.restart_at`` kills the router and starts it again
on its endpoint (`bounce`): the clients reconnect by themselves.

What the summary adds (``security``): the endpoint, what was enforced, the router's exit, and
``rejected_messages`` — operator messages the controller refused (the last RobotState's
`link.rejected_messages`). Messages the router's ACL dropped are not counted: Zenoh 1.10 drops
them silently, with no counter or callback the Python API exposes.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from sharedctl.protocol import keys

from ..children import Child, python_module
from .credentials import Credentials, generate
from .signing import Signer
from .roles import ROLES
from .zenoh_config import check_endpoint, client_config, open_from_file, router_config, write_config

READY_TIMEOUT = 30.0   # s for the router to listen and a role to show its liveliness token
OPERATOR = "operator"  # the console's operator: its name at the router and in its signed commands


def add_arguments(p) -> None:
    p.add_argument("--secure", action="store_true",
                   help="throw-away credentials and certificates; a router with usrpwd, mTLS and ACL; every process "
                        "a client with its role's credentials (--zenoh-listen: the router's endpoint, tcp/ or tls/)")


def _start_router(argv: list[str], log_dir: Path, name: str = "router") -> Child:
    """The router module alone (`sharedctl router` without importing every other sub-command: it is
    up seconds sooner on a busy host), in its own session, output to log_dir/NAME.log."""
    log = log_dir / f"{name}.log"
    with open(log, "wb") as out:
        popen = subprocess.Popen([*python_module("sharedctl.services.security.router_command"), *argv],
                                 env=dict(os.environ, PYTHONUNBUFFERED="1"), stdin=subprocess.DEVNULL, stdout=out,
                                 stderr=subprocess.STDOUT, start_new_session=True)
    return Child("router", popen, log)


@dataclass
class SecureStack:
    enabled: bool = False
    endpoint: str | None = None
    directory: Path | None = None
    creds: Credentials | None = None
    configs: dict = field(default_factory=dict)       # role (and "router") -> Path
    router: object | None = None                      # children.Child
    session: object | None = None                     # the observer's zenoh.Session (the demo closes it)
    operator: object | None = None                    # an operator-role session for the faults that publish
    log_dir: Path | None = None
    backstop: str = ""
    console_endpoint: str | None = None               # the console's own router (link faults: the relay between)
    console_router: object | None = None              # its children.Child
    bounced: list = field(default_factory=list)       # routers killed on purpose (router.restart_at)

    @classmethod
    def from_args(cls, args, free_port, faults=None) -> "SecureStack":
        """Inert without --secure; raises ValueError on a bad endpoint or an unsupported combination."""
        bounces = faults is not None and any(f.action == "bounce" for f in faults.plan.processes)
        if not getattr(args, "secure", False):
            if bounces:
                raise ValueError("router.restart_at needs --secure (without it there is no router)")
            return cls()
        endpoint = check_endpoint(args.zenoh_listen) if args.zenoh_listen else f"tls/127.0.0.1:{free_port()}"
        console = f"{endpoint.split('/', 1)[0]}/127.0.0.1:{free_port()}" if faults is not None and faults.needs_relay \
            else None
        return cls(enabled=True, endpoint=endpoint, console_endpoint=console)

    # ----- the run ---------------------------------------------------------------
    def start(self, log_dir: Path, backstop: str, wait_listening, robot_id: str = "robot1",
              operators: tuple[str, ...] = (OPERATOR,)) -> None:
        """Credentials and configs in a temporary directory (`operators`: the named operators, each allowed
        `robot_id` only), the router child, the observer session."""
        if not self.enabled:
            return
        self.directory = Path(tempfile.mkdtemp(prefix="sharedctl-secure-"))
        self.creds = generate(self.directory / "credentials", ROLES,
                              operators={name: (robot_id,) for name in operators})
        self.configs["router"] = write_config(self.directory / "router.json5",
                                              router_config(self.creds, [self.endpoint]), "sharedctl demo --secure")
        for name in self.creds.users:
            self.configs[name] = write_config(self.directory / f"{name}.json5",
                                              client_config(name, self.creds, [self.endpoint]), f"demo {name}")
        self.log_dir, self.backstop, self.wait_listening = log_dir, backstop, wait_listening
        self.router = _start_router(["--config", str(self.configs["router"]), "--duration", backstop], log_dir)
        if self.console_endpoint is not None:
            ep = [self.console_endpoint]
            self.configs["console-router"] = write_config(self.directory / "console-router.json5",
                                                          router_config(self.creds, ep), "the console's router")
            self.configs["console"] = write_config(self.directory / "console.json5",
                                                   client_config(OPERATOR, self.creds, ep), "console via the relay")
            self.configs["relay-console-side"] = write_config(self.directory / "relay-console-side.json5",
                                                              client_config("controller", self.creds, ep),
                                                              "the relay on the console's router")
            self.console_router = _start_router(["--config", str(self.configs["console-router"]),
                                                 "--duration", backstop], log_dir, "console-router")
            if not wait_listening(self.console_endpoint, self.console_router, READY_TIMEOUT):
                raise RuntimeError(f"the console's router did not come up on {self.console_endpoint}")
        if not wait_listening(self.endpoint, self.router, READY_TIMEOUT):
            raise RuntimeError(f"router did not come up on {self.endpoint}")
        self.session = open_from_file(self.configs["observer"])

    def operator_session(self):
        """A session of the console's operator (opened once), for the faults that publish operator commands."""
        if self.operator is None:
            self.operator = open_from_file(self.configs[OPERATOR])
        return self.operator

    def signer(self, name: str) -> Signer | None:
        """Operator `name`'s signer (None when not secure)."""
        return Signer.from_file(self.creds.signing_key(name), name) if self.enabled else None

    def bounce(self, down: float) -> dict:
        """router.restart_at: SIGKILL the router, wait `down` s, start it again on its endpoint."""
        old = self.router
        old.popen.kill()
        old.popen.wait()
        old.exit_code, old.stop_seconds = old.popen.returncode, 0.0
        self.bounced.append(old)
        time.sleep(down)
        self.router = _start_router(["--config", str(self.configs["router"]), "--duration", self.backstop],
                                    self.log_dir, f"router.{len(self.bounced)}")
        back = self.wait_listening(self.endpoint, self.router, READY_TIMEOUT)
        return {"down_s": down, "back_listening": back, "killed_pid": old.popen.pid, "pid": self.router.popen.pid}

    def zenoh_args(self, role: str, plain: list[str]) -> list[str]:
        """A child's Zenoh arguments: its role's configuration file (and the operator's identity: the console
        signs as `operator`, the controller trusts the operators file), or `plain` when not secure."""
        if not self.enabled:
            return plain
        identity = {"operator": ["--operator-id", OPERATOR, "--signing-key", str(self.creds.signing_key(OPERATOR))],
                    "controller": ["--operators", str(self.creds.trust_file)]}.get(role, [])
        config = role if role != "operator" else "console" if self.console_endpoint is not None else OPERATOR
        return ["--zenoh-config", str(self.configs[config]), *identity]

    def relay_args(self) -> list[str] | None:
        """The fault relay's Zenoh arguments behind the routers (None when not secure)."""
        if not self.enabled or self.console_endpoint is None:
            return None
        return ["--console-config", str(self.configs["relay-console-side"]),
                "--controller-config", str(self.configs[OPERATOR])]

    def wait_up(self, role: str, robot_id: str, child, timeout: float, plain_wait) -> bool:
        """Secure: the role's liveliness token is visible through the router; else `plain_wait()`."""
        if not self.enabled:
            return plain_wait()
        key = keys.alive_key(robot_id, role)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if child.popen.poll() is not None:
                return False
            if any(reply.ok is not None for reply in self.session.liveliness().get(key, timeout=0.5)):
                return True
            time.sleep(0.05)
        return False

    def open_session(self, plain_open):
        """The demo's measuring session: the observer's (opened in `start`), else `plain_open()`."""
        return self.session if self.enabled else plain_open()

    def stop(self) -> None:
        """Stop the router (after every client is gone) and remove the credentials."""
        if self.session is not None and not self.session.is_closed():
            self.session.close()     # the demo closes it, unless the run failed before using it
        if self.operator is not None and not self.operator.is_closed():
            self.operator.close()
        for router in (self.router, self.console_router):
            if router is not None:
                router.stop()
        if self.directory is not None:
            shutil.rmtree(self.directory, ignore_errors=True)

    # ----- the summary -----------------------------------------------------------
    @property
    def clean(self) -> bool:
        return not self.enabled or (self.router is not None and self.router.clean
                                    and (self.console_router is None or self.console_router.clean))

    def summary(self, rec) -> dict:
        """`security` and `rejected_messages` for the demo's JSON (nothing when not secure)."""
        if not self.enabled:
            return {}
        with rec.lock:
            last = rec.states[-1][1] if rec.states else None
        return {
            "rejected_messages": int(last.link.rejected_messages) if last is not None else None,
            "security": {
                "router_endpoint": self.endpoint,
                "authentication": "usrpwd"
                                  + (" + mTLS client certificates" if self.endpoint.startswith("tls/") else ""),
                "access_control": "default deny; per-role rules, each operator its robot's keys only "
                                  "(services/security/roles.py)",
                "operator_identity": "Ed25519-signed commands and lease requests, verified by the controller "
                                     f"(operators: {', '.join(self.creds.operators)})",
                "roles": {"robot": "robot", "controller": "controller", "console": "operator", "demo": "observer"},
                "router": self.router.report() if self.router is not None else None,
                "console_router": self.console_router.report() if self.console_router is not None else None,
                "routers_killed_on_purpose": [r.report() for r in self.bounced],
                "acl_denials_counted": False,
                "undecodable_at_demo": rec.rejected,
                "credentials_removed": self.directory is not None and not self.directory.exists(),
            },
        }
