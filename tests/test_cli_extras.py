"""A command whose extra is not installed stops with a message naming the extra, not a traceback."""
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from sharedctl.services import cli

PYPROJECT = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())


def extra_of(module: str) -> str:
    """The extra of pyproject.toml whose requirements include the distribution that provides `module`."""
    dists = {canonicalize_name(d) for d in packages_distributions()[module]}
    extras = [name for name, reqs in PYPROJECT["project"]["optional-dependencies"].items()
              if name != "test" and any(canonicalize_name(Requirement(r).name) in dists for r in reqs)]
    assert len(extras) == 1, extras
    return extras[0]


def expected(command: str, module: str) -> str:
    extra = extra_of(module)
    return (f"sharedctl {command}: needs {module}, which comes with the '{extra}' extra: "
            f"pip install 'sharedctl[{extra}]'\n")


@pytest.fixture
def without(monkeypatch):
    """Make `import NAME` fail for the given modules, and forget every study module imported so far."""
    def block(*names):
        for key in list(sys.modules):
            if key.split(".")[0] in names or key.startswith(("sharedctl.services.studies", "sharedctl.baselines",
                                                             "sharedctl.services.foxglove")):
                monkeypatch.delitem(sys.modules, key)
        for name in names:
            monkeypatch.setitem(sys.modules, name, None)
    return block


@pytest.mark.parametrize("argv,module", [
    (["plot", "--out", "figure.png", "run.json"], "matplotlib"),
    (["plot", "--help"], "matplotlib"),
    (["compare", "--quick"], "quadprog"),
    (["foxglove", "--connect", "tcp/127.0.0.1:7447"], "foxglove"),
    (["console", "--input", "gamepad", "--headless", "--duration", "1"], "evdev"),
])
def test_a_command_whose_module_needs_a_missing_extra_exits_2_naming_the_extra(without, capsys, argv, module):
    without(module)
    assert cli.main(argv) == 2
    assert capsys.readouterr().err == expected(argv[0], module)


def test_a_study_that_imports_its_extra_only_while_running_names_the_extra(without, capsys, tmp_path):
    without("matplotlib")
    assert cli.main(["paper", "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == expected("paper", "matplotlib")


def test_an_option_that_needs_a_missing_extra_is_refused_before_the_run(without, capsys, tmp_path):
    without("matplotlib")
    assert cli.main(["sim", "paper_convex", "--plot", str(tmp_path / "run.png")]) == 2
    out = capsys.readouterr()
    assert out.err == expected("sim", "matplotlib")
    assert out.out == ""                      # the simulation's summary table was never printed


def test_a_demo_with_a_live_view_needs_the_foxglove_extra(without, capsys):
    without("foxglove")
    assert cli.main(["demo", "--foxglove", "127.0.0.1:8765"]) == 2
    assert "needs foxglove-sdk, which comes with the 'foxglove' extra" in capsys.readouterr().err


def test_help_still_lists_every_command_when_the_extras_are_missing(without, capsys):
    without("matplotlib", "quadprog")
    with pytest.raises(SystemExit) as stop:
        cli.main(["--help"])
    assert stop.value.code == 0
    rows = [line.split(None, 1) for line in capsys.readouterr().out.splitlines() if line.startswith("    ")]
    assert set(cli.COMMANDS) <= {row[0] for row in rows}
    assert ["plot", "(needs pip install 'sharedctl[plots]')"] in rows


def test_a_missing_runtime_module_is_not_mistaken_for_an_extra(without, capsys):
    without("rich")
    assert cli.main(["fuzz", "--count", "1"]) == 3
    err = capsys.readouterr().err
    assert "cannot import 'rich" in err and "sharedctl fuzz" in err and "runtime dependencies" in err, err


def test_a_missing_module_of_this_project_is_a_loud_error_not_a_shorter_command_list(monkeypatch, capsys):
    """Before, a packaging mistake that left a subpackage out showed as "invalid choice: 'router' (choose from )"."""
    for key in [k for k in sys.modules if k.startswith("sharedctl.services.security")]:
        monkeypatch.delitem(sys.modules, key)
    monkeypatch.setitem(sys.modules, "sharedctl.services.security", None)
    for argv in (["router", "--help"], ["--help"]):
        assert cli.main(argv) == 3
        err = capsys.readouterr().err
        assert "cannot import 'sharedctl.services.security" in err and "sharedctl router" in err, err


def test_the_version_is_the_installed_distributions(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as stop:
        cli.main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out == f"sharedctl {version('sharedctl')}\n"


@pytest.mark.parametrize("argv", [["controller", "--ros2", "0"], ["controller", "--ros2"], ["demo", "--ros2", "3"]])
def test_ros2_without_rosbags_is_refused_before_the_run_naming_the_extra(without, capsys, argv):
    """Domain 0 is a value, not "off": the check must not take it for a missing option."""
    without("rosbags")
    assert cli.main(argv) == 2
    out = capsys.readouterr()
    assert out.err == expected(argv[0], "rosbags") and out.out == ""


def test_the_controller_needs_no_rosbags_without_ros2(without, capsys):
    without("rosbags")
    with pytest.raises(SystemExit) as stop:
        cli.main(["controller", "--help"])
    assert stop.value.code == 0 and "--ros2" in capsys.readouterr().out
