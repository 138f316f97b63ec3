"""Specification of the Zenoh key-expression layout."""
from __future__ import annotations

import pytest
from hypothesis import given

from protocol_strategies import tokens
from sharedctl.protocol import keys
from sharedctl.protocol.errors import KeyExprError


def test_operator_command_key():
    assert keys.operator_cmd_key("rover1") == "sharedctl/v1/rover1/operator/cmd"


def test_state_key():
    assert keys.state_key("rover1") == "sharedctl/v1/rover1/state"


def test_events_key():
    assert keys.events_key("rover1") == "sharedctl/v1/rover1/events"


def test_alive_key_ends_with_the_role():
    assert keys.alive_key("rover1", "controller") == "sharedctl/v1/rover1/alive/controller"


def test_truth_key():
    assert keys.truth_key("rover1") == "sharedctl/v1/rover1/truth"


def test_lease_key():
    assert keys.lease_key("rover1") == "sharedctl/v1/rover1/control/lease"


def test_alive_pattern_matches_every_role_of_one_robot():
    assert keys.alive_pattern("rover1") == "sharedctl/v1/rover1/alive/*"


def test_robot_pattern_matches_everything_of_one_robot():
    assert keys.robot_pattern("rover1") == "sharedctl/v1/rover1/**"


def test_layout_segment_is_the_wire_major():
    assert keys.PREFIX == "sharedctl/v1"


@pytest.mark.parametrize("robot", ["", "a/b", "*", "**", "$*", "a#b", "a?", "a b", "-lead", "_lead", "é",
                                   "a" * 65, "rover\n"])
def test_invalid_robot_id_is_refused(robot):
    with pytest.raises(KeyExprError):
        keys.state_key(robot)


def test_non_string_robot_id_is_refused():
    with pytest.raises(KeyExprError):
        keys.state_key(3)


@pytest.mark.parametrize("role", ["", "ops/x", "*", "a$", "a.b"])
def test_invalid_role_is_refused(role):
    with pytest.raises(KeyExprError):
        keys.alive_key("rover1", role)


def test_robot_id_of_64_characters_is_accepted():
    assert keys.state_key("r" * 64).split("/")[2] == "r" * 64


@given(tokens, tokens)
def test_every_built_key_parses_back_to_its_parts(robot, role):
    built = {
        "operator_cmd": keys.operator_cmd_key(robot), "state": keys.state_key(robot),
        "events": keys.events_key(robot), "alive": keys.alive_key(robot, role),
        "truth": keys.truth_key(robot), "lease": keys.lease_key(robot),
    }
    parsed = {kind: keys.parse_key(key) for kind, key in built.items()}
    assert parsed == {kind: keys.ParsedKey(robot, kind, role if kind == "alive" else None) for kind in built}


@given(tokens, tokens)
def test_built_keys_contain_no_wildcard_or_special_characters(robot, role):
    key = keys.alive_key(robot, role)
    assert not set(key) & set("*$#? ")


@pytest.mark.parametrize("key", [
    "sharedctl/v2/rover1/state", "other/v1/rover1/state", "sharedctl/v1/rover1/status",
    "sharedctl/v1/*/state", "sharedctl/v1/rover1/alive/*", "sharedctl/v1/rover1/state/", "sharedctl/v1/rover1",
    "sharedctl/v1/rover1/operator/cmd/extra", "sharedctl/v1//state",
])
def test_parse_key_refuses_keys_outside_the_layout(key):
    with pytest.raises(KeyExprError):
        keys.parse_key(key)


def test_parse_key_refuses_non_strings():
    with pytest.raises(KeyExprError):
        keys.parse_key(b"sharedctl/v1/rover1/state")
