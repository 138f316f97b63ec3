"""Security configuration without a network: credentials, the per-role ACL, config files and their rules.

(The same configurations with real Zenoh sessions: test_security_auth.py.)"""
from __future__ import annotations

import json
import stat
from pathlib import Path

import pytest
import zenoh
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from sharedctl.protocol import keys
from sharedctl.services.security import credentials, roles
from sharedctl.services.security.zenoh_config import (ZenohConfigError, check_endpoint, client_config, from_file,
                                                      router_config, write_config)
from sharedctl.services.zenoh_session import EndpointError

DEPLOY = Path(__file__).resolve().parents[2] / "deploy" / "zenoh"


def _cert(path: Path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def _common_name(cert: x509.Certificate) -> str:
    return cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value


@pytest.fixture(scope="module")
def creds(tmp_path_factory):
    return credentials.generate(tmp_path_factory.mktemp("creds"))


# ----- credentials ------------------------------------------------------------
def test_each_role_certificate_names_the_role_and_is_signed_by_the_site_ca(creds):
    ca = _cert(creds.ca)
    for role in roles.ROLES:
        cert = _cert(creds.certificate(role))
        assert _common_name(cert) == role
        assert cert.issuer == ca.subject
        cert.verify_directly_issued_by(ca)      # raises if the signature does not verify
        assert cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca is False
        assert ExtendedKeyUsageOID.CLIENT_AUTH in cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value


def test_the_router_certificate_is_a_server_certificate_for_loopback(creds):
    cert = _cert(creds.certificate("router"))
    sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert sans.get_values_for_type(x509.DNSName) == ["localhost"]
    assert [str(ip) for ip in sans.get_values_for_type(x509.IPAddress)] == ["127.0.0.1"]
    assert ExtendedKeyUsageOID.SERVER_AUTH in cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value


def test_the_ca_may_sign_and_nothing_else_is_a_ca(creds):
    ca = _cert(creds.ca)
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca is True
    assert ca.extensions.get_extension_for_class(x509.KeyUsage).value.key_cert_sign is True


def test_private_keys_and_passwords_are_readable_by_the_owner_only(creds):
    secrets = ([creds.private_key(r) for r in (*roles.ROLES, "router")]
               + [creds.dictionary, creds.directory / "ca-key.pem"])
    secrets += [creds.directory / f"{r}.password" for r in roles.ROLES]
    for path in secrets:
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, path


def test_the_dictionary_holds_one_distinct_password_per_role(creds):
    lines = creds.dictionary.read_text().splitlines()
    pairs = dict(line.split(":", 1) for line in lines)
    assert sorted(pairs) == sorted(roles.ROLES)
    assert len(set(pairs.values())) == len(roles.ROLES)
    assert all(len(p) >= 32 for p in pairs.values())
    assert credentials.load(creds.directory).users == pairs


def test_a_role_name_that_is_not_a_token_is_refused(tmp_path):
    with pytest.raises(roles.RoleError):
        credentials.generate(tmp_path, roles=("operator", "bad/role"))


# ----- the access-control list -----------------------------------------------------
def _writes(acl: dict, role: str) -> dict[str, set[str]]:
    """message kind -> key expressions the router accepts from `role` (flow ingress, allow)."""
    policy = next(p for p in acl["policies"] if p["subjects"] == [f"{role}-subject"])
    out: dict[str, set[str]] = {}
    for rule in acl["rules"]:
        if rule["id"] in policy["rules"] and "ingress" in rule["flows"] and rule["permission"] == "allow":
            for kind in rule["messages"]:
                out.setdefault(kind, set()).update(rule["key_exprs"])
    return out


def test_the_router_denies_by_default():
    acl = roles.access_control()
    assert acl["enabled"] is True and acl["default_permission"] == "deny"


def test_an_observer_may_only_declare_subscriptions():
    writes = _writes(roles.access_control(), "observer")
    assert set(writes) == set(roles.READ_INGRESS)
    assert "put" not in writes and "query" not in writes and "reply" not in writes


def test_the_operator_may_put_only_operator_keys_and_query_the_lease():
    writes = _writes(roles.access_control(), "operator")
    assert writes["put"] == {"sharedctl/v1/*/operator/cmd", "sharedctl/v1/*/alive/operator"}
    assert writes["query"] == {"sharedctl/v1/*/control/lease"}
    assert "reply" not in writes and "declare_queryable" not in writes


def test_only_the_controller_may_publish_state_and_answer_the_lease():
    acl = roles.access_control()
    for role in roles.ROLES:
        writes = _writes(acl, role)
        owns_state = "sharedctl/v1/*/state" in writes.get("put", set())
        answers = "sharedctl/v1/*/control/lease" in writes.get("reply", set())
        assert owns_state == answers == (role == "controller"), role


def test_only_the_robot_may_publish_ground_truth():
    acl = roles.access_control()
    assert [r for r in roles.ROLES if "sharedctl/v1/*/truth" in _writes(acl, r).get("put", set())] == ["robot"]


def test_rule_keys_cover_the_protocol_keys():
    concrete = {"operator/cmd": keys.operator_cmd_key("r1"), "state": keys.state_key("r1"),
                "truth": keys.truth_key("r1"), "control/lease": keys.lease_key("r1")}
    for suffix, key in concrete.items():
        assert zenoh.KeyExpr(f"sharedctl/v1/*/{suffix}").includes(zenoh.KeyExpr(key))


def test_under_mtls_a_subject_needs_the_user_and_the_certificate_name():
    subjects = roles.access_control(tls=True, usrpwd=True)["subjects"]
    assert {"id": "operator-subject", "usernames": ["operator"], "cert_common_names": ["operator"]} in subjects


# ----- configuration files -------------------------------------------------------
def test_tls_and_tcp_loopback_endpoints_are_accepted():
    assert check_endpoint("tls/127.0.0.1:7447") == "tls/127.0.0.1:7447"
    assert check_endpoint("tcp/127.0.0.1:7447") == "tcp/127.0.0.1:7447"


@pytest.mark.parametrize("endpoint", ["tls/0.0.0.0:7447", "tcp/192.168.1.2:7447", "udp/127.0.0.1:7447",
                                      "tls/127.0.0.1"])
def test_endpoints_off_this_host_or_without_a_port_are_refused(endpoint):
    with pytest.raises(EndpointError):
        check_endpoint(endpoint)


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cfg.json5"
    path.write_text(text)
    return path


def test_a_file_with_a_remote_endpoint_is_refused(tmp_path):
    path = _write(tmp_path, '{ mode: "client", connect: { endpoints: ["tcp/10.0.0.5:7447"] } }')
    with pytest.raises(ZenohConfigError, match="not a loopback"):
        from_file(path)


def test_a_router_without_listen_endpoints_is_refused(tmp_path):
    # Zenoh's default for a router is tcp/[::]:7447: every interface
    with pytest.raises(ZenohConfigError, match="listen/endpoints"):
        from_file(_write(tmp_path, '{ mode: "router" }'))


def test_a_file_that_turns_scouting_on_is_refused(tmp_path):
    path = _write(tmp_path, '{ mode: "client", connect: { endpoints: ["tcp/127.0.0.1:7447"] },'
                            ' scouting: { multicast: { enabled: true } } }')
    with pytest.raises(ZenohConfigError, match="scouting"):
        from_file(path)


def test_scouting_is_switched_off_when_the_file_says_nothing(tmp_path):
    cfg = from_file(_write(tmp_path, '{ mode: "client", connect: { endpoints: ["tcp/127.0.0.1:7447"] } }'))
    assert json.loads(cfg.get_json("scouting/multicast/enabled")) is False
    assert json.loads(cfg.get_json("scouting/gossip/enabled")) is False


def test_paths_in_a_file_are_relative_to_the_file(tmp_path):
    path = _write(tmp_path, '// comment\n{ mode: "client", connect: { endpoints: ["tls/127.0.0.1:7447"] },'
                            ' transport: { link: { tls: { root_ca_certificate: "creds/ca.pem" } } } }')
    cfg = from_file(path)
    assert json.loads(cfg.get_json("transport/link/tls/root_ca_certificate")) == str(tmp_path / "creds" / "ca.pem")


def test_command_line_endpoints_replace_the_files(tmp_path):
    path = _write(tmp_path, '{ mode: "client", connect: { endpoints: ["tcp/127.0.0.1:7447"] } }')
    cfg = from_file(path, connect=["tcp/127.0.0.1:9000"])
    assert json.loads(cfg.get_json("connect/endpoints")) == ["tcp/127.0.0.1:9000"]
    with pytest.raises(ZenohConfigError):
        from_file(path, connect=["tcp/10.1.1.1:9000"])


def test_a_syntax_error_is_a_typed_error(tmp_path):
    with pytest.raises(ZenohConfigError):
        from_file(_write(tmp_path, '{ mode: "client", connect: '))
    with pytest.raises(ZenohConfigError, match="no such file"):
        from_file(tmp_path / "absent.json5")


def test_generated_configs_read_back_with_their_credentials(creds, tmp_path):
    router = write_config(tmp_path / "router.json5", router_config(creds, ["tls/127.0.0.1:7447"]), "router")
    operator = write_config(tmp_path / "operator.json5", client_config("operator", creds, ["tls/127.0.0.1:7447"]))
    r, o = from_file(router), from_file(operator)
    assert json.loads(r.get_json("transport/auth/usrpwd/dictionary_file")) == str(creds.dictionary)
    assert json.loads(r.get_json("transport/link/tls/enable_mtls")) is True
    assert json.loads(o.get_json("transport/auth/usrpwd/password")) == creds.users["operator"]
    assert json.loads(o.get_json("transport/link/tls/connect_certificate")) == str(creds.certificate("operator"))
    assert stat.S_IMODE(operator.stat().st_mode) == 0o600


# ----- the examples in deploy/zenoh ---------------------------------------------------
@pytest.mark.parametrize("name", ["router", *roles.ROLES])
def test_deploy_examples_are_valid_and_follow_the_rules(name):
    cfg = from_file(DEPLOY / f"{name}.json5")
    mode = json.loads(cfg.get_json("mode"))
    assert mode == ("router" if name == "router" else "client")
    if name != "router":
        assert json.loads(cfg.get_json("transport/auth/usrpwd/user")) == name
        assert json.loads(cfg.get_json("transport/link/tls/connect_certificate")).endswith(f"/{name}.pem")


def test_the_deploy_router_acl_is_the_one_the_code_builds():
    cfg = from_file(DEPLOY / "router.json5")
    acl = json.loads(cfg.get_json("access_control"))
    expected = roles.access_control(tls=True, usrpwd=True)

    def normal(entries, fields):
        return sorted(({k: e[k] for k in fields if e.get(k) is not None} for e in entries), key=lambda e: e["id"])

    assert acl["default_permission"] == "deny" and acl["enabled"] is True
    rule_fields = ("id", "permission", "flows", "messages", "key_exprs")
    assert normal(acl["rules"], rule_fields) == normal(expected["rules"], rule_fields)
    subject_fields = ("id", "usernames", "cert_common_names")
    assert normal(acl["subjects"], subject_fields) == normal(expected["subjects"], subject_fields)
    policy_fields = ("id", "rules", "subjects")
    assert normal(acl["policies"], policy_fields) == normal(expected["policies"], policy_fields)


@pytest.mark.parametrize("config,listen,connect,expected", [
    ("/etc/c.json5", [], [], "config /etc/c.json5"),
    (None, ["tcp/127.0.0.1:1"], [], "listen tcp/127.0.0.1:1"),
    ("/etc/c.json5", [], ["tls/127.0.0.1:7447"], "connect tls/127.0.0.1:7447 config /etc/c.json5"),
])
def test_a_start_line_says_how_the_session_connects_whatever_was_given(config, listen, connect, expected):
    """Before, a controller given only --zenoh-config printed "Zenoh ," in its start line."""
    from sharedctl.services.security.zenoh_config import describe

    assert describe(config, listen, connect) == expected
