"""Service settings files (`--service-config FILE.toml`): deploy/config/*.toml and the reader
(services/service_config.py)."""
import pytest
import yaml

from sharedctl.services.cli import build_parser, main
from sharedctl.services.metrics import address_from_args
from sharedctl.services.service_config import ServiceConfigError, expand

from .deploy_files import DEPLOY, parse_command


@pytest.mark.parametrize("name", ["robot", "controller", "console"])
def test_each_example_settings_file_parses_as_its_command(name):
    args = parse_command([name, "--service-config", str(DEPLOY / "config" / f"{name}.toml")])
    assert args.robot_id == "robot1"


def test_the_site_controller_takes_control_explicitly_and_bounds_command_age():
    args = parse_command(["controller", "--service-config", str(DEPLOY / "config" / "controller.toml")])
    assert args.lease == "explicit" and args.lease_expiry_ms == 1000.0
    assert args.max_command_age_ms == 500.0
    assert args.max_clock_skew_ms is None       # docs/deploy.md: only where every host's clock is synchronised


def test_a_command_line_option_after_the_file_wins(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('rate = 250.0\nquiet = true\ncan-option = ["port=1", "bitrate=500000"]\n')
    argv = expand(["controller", "--service-config", str(path), "--rate", "400", "--can-option", "port=2"],
                  build_parser())
    assert argv == ["controller", "--quiet", "--can-option", "port=1", "--can-option", "bitrate=500000",
                    "--rate", "400", "--can-option", "port=2"]        # a repeatable option: both are used
    assert parse_command(argv).rate == 400.0


def test_a_command_line_option_overrules_the_files_option_of_its_exclusive_group():
    """docs/deploy.md: a later option wins. Before, the site console.toml's `scenario` and `--script` on the command
    line were refused together ("--script: not allowed with argument --scenario")."""
    console = str(DEPLOY / "config" / "console.toml")
    args = parse_command(["console", "--service-config", console, "--script", "adversarial_wall"])
    assert args.script == "adversarial_wall" and args.scenario is None
    assert args.operator_id == "operator" and args.signing_key.endswith("operator.signing-key.pem")
    args = parse_command(["console", "--service-config", console])
    assert args.scenario == "paper_convex" and args.script is None


@pytest.mark.parametrize("text,message", [
    ("no-such-option = 1\n", "unknown key 'no-such-option'"),
    ("quiet = 1\n", "quiet: expected true or false"),
    ("[controller]\nrate = 1\n", "controller"),
    ("rate = [[1]]\n", "rate: expected a string or a number"),
    ("rate = \n", "not valid TOML"),
])
def test_a_bad_settings_file_is_refused_naming_the_key(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ServiceConfigError, match=message):
        expand(["controller", "--service-config", str(path)], build_parser())


def test_the_command_line_exits_2_on_a_bad_settings_file(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text("ratee = 500\n")
    assert main(["controller", "--service-config", str(path)]) == 2
    assert "ratee" in capsys.readouterr().err


@pytest.mark.parametrize("value, expected", [("true", True), ("false", False)])
def test_a_default_on_switch_can_be_turned_off_in_a_settings_file(tmp_path, value, expected):
    path = tmp_path / "controller.toml"
    path.write_text(f"sensor-sync = {value}\n")
    argv = expand(["controller", "--service-config", str(path)], build_parser())
    assert build_parser().parse_args(argv).sensor_sync is expected


def test_the_site_scrape_configuration_scrapes_the_loopback_metrics_endpoints_of_the_settings_files():
    scraped = {job["job_name"]: target for job in yaml.safe_load((DEPLOY / "prometheus.yml").read_text())
               ["scrape_configs"] for target in job["static_configs"][0]["targets"]}
    for name in ("controller", "robot"):
        args = parse_command([name, "--service-config", str(DEPLOY / "config" / f"{name}.toml")])
        address = address_from_args(args)
        assert address.host == "127.0.0.1" and not args.metrics_allow_remote
        assert scraped[f"sharedctl-{name}"] == f"{address.host}:{address.port}"
