"""The exporter's options (services/metrics.py) and the metric names of both collectors, pure: no socket."""
from __future__ import annotations

import re

import pytest
from prometheus_client import CollectorRegistry
from prometheus_client.openmetrics import exposition as openmetrics
from prometheus_client.openmetrics.parser import text_string_to_metric_families as parse_openmetrics

from sharedctl.services.cli import build_parser
from sharedctl.services.controller.metrics import ControllerCollector
from sharedctl.services.metrics import MetricsAddress, MetricsAddressError, address_from_args, parse_address
from sharedctl.services.robot.metrics import RobotCollector

from .test_controller_loop import arm, make_daemon, operator
from .test_robot_metrics import process_with


@pytest.mark.parametrize("text, expected", [
    ("9464", MetricsAddress("127.0.0.1", 9464)),
    ("127.0.0.1:0", MetricsAddress("127.0.0.1", 0)),
    ("localhost:9100", MetricsAddress("127.0.0.1", 9100)),
    ("127.0.0.2:9100", MetricsAddress("127.0.0.2", 9100)),
    ("[::1]:9100", MetricsAddress("::1", 9100)),
])
def test_a_loopback_address_or_a_bare_port_is_taken(text, expected):
    assert parse_address(text) == expected


@pytest.mark.parametrize("text", ["0.0.0.0:9100", "192.0.2.7:9100", "[::]:9100"])
def test_a_host_that_is_not_loopback_is_refused_unless_allowed(text):
    with pytest.raises(MetricsAddressError, match="--metrics-allow-remote"):
        parse_address(text)
    assert parse_address(text, allow_remote=True).port == 9100


@pytest.mark.parametrize("text", ["", "127.0.0.1:", "127.0.0.1:65536", "127.0.0.1:-1", "127.0.0.1:http",
                                  "example.org:9100", "::1:9100", "127.0.0.1:9100:1"])
def test_a_malformed_address_is_a_typed_error(text):
    with pytest.raises(MetricsAddressError):
        parse_address(text)


@pytest.mark.parametrize("command", ["robot", "controller"])
def test_both_processes_take_the_options(command):
    parser = build_parser(command)
    assert address_from_args(parser.parse_args([command])) is None
    args = parser.parse_args([command, "--metrics", "192.0.2.7:9100", "--metrics-allow-remote"])
    assert address_from_args(args) == MetricsAddress("192.0.2.7", 9100)
    with pytest.raises(MetricsAddressError):
        address_from_args(parser.parse_args([command, "--metrics", "192.0.2.7:9100"]))


FORBIDDEN_UNITS = re.compile(r"_(ms|us|ns|milliseconds|microseconds|minutes|hours|hz|khz|percent|kb|mb)(_|$)")


def families():
    """Every family both collectors yield, with every optional figure present, as OpenMetrics parses them
    (its parser is strict: a counter's samples must end in _total, an info's in _info, buckets in order…)."""
    daemon = make_daemon()
    arm(daemon)
    operator(daemon, 1, 10.003)
    daemon.tick(10.004)
    daemon.master.probe.probe_sent(0, 10.0)
    daemon.master.probe.reply(0, 10.0004)
    registry = CollectorRegistry()
    registry.register(ControllerCollector(daemon, "ce"))
    registry.register(RobotCollector(process_with([])))
    return list(parse_openmetrics(openmetrics.generate_latest(registry).decode()))


def test_names_follow_the_prometheus_conventions():
    found = families()
    assert len(found) > 30
    for family in found:
        name = family.name
        assert re.fullmatch(r"sharedctl_(controller|robot)(_[a-z0-9]+)*", name), name
        assert not FORBIDDEN_UNITS.search(name), f"{name}: not a base unit"
        assert family.documentation, name
        if family.type == "counter":
            assert all(s.name == name + "_total" for s in family.samples), name
        else:
            assert not name.endswith("_total"), name
        if family.type == "histogram":
            assert name.endswith("_seconds"), name
        for unit in ("seconds", "hertz", "ratio", "bytes"):     # OpenMetrics' UNIT says the suffix
            assert (family.unit == unit) == name.endswith("_" + unit), name
