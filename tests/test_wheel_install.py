"""The wheel as a user gets it: built from the tracked tree without a warning, installed non-editable into a fresh
virtual environment, and run from a clone's root (the Docker image's layout: its WORKDIR holds copies of the three
source folders) and from an empty directory.

The tests' own environment is an editable install, which hides what a non-editable one meets: before, every command
that starts children failed from a clone's root (`python -m` put the working directory first on the import path, and
the source folder `sharedctl/`, which has no `services/`, hid the installed package). Offline: the new environment
reuses the dependencies already installed in this one (a path to its site-packages; none of its .pth files run)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

pytestmark = [pytest.mark.processes, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[1]


def _tracked_tree(dest: Path) -> list[str]:
    """Copy the repository's tracked files (what a fresh clone holds) to `dest`, so the build leaves nothing
    behind; returns their names."""
    if (ROOT / ".git").exists() and shutil.which("git"):
        files = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-co", "--exclude-standard"], check=True,
                               capture_output=True, text=True).stdout.splitlines()
    else:                                               # an unpacked sdist: it is the tracked tree
        files = [str(p.relative_to(ROOT)) for p in ROOT.rglob("*") if p.is_file() and ".venv" not in p.parts]
    for name in files:
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    return [name for name in files if (dest / name).is_file()]


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wheel")
    tree = tmp / "src"
    files = _tracked_tree(tree)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}   # its notices are not the build's
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
                            "-w", str(tmp / "dist"), str(tree)], capture_output=True, text=True, env=env, timeout=300)
    assert build.returncode == 0, build.stderr[-2000:]
    wheel = next((tmp / "dist").glob("sharedctl-*.whl"))
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True).stdout.strip())
    (site / "reuse-installed-dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    install = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
                              "--no-index", str(wheel)], capture_output=True, text=True, timeout=300)
    assert install.returncode == 0, install.stderr[-2000:]
    return {"build": build, "wheel": wheel, "venv": venv, "python": python, "tmp": tmp, "files": set(files)}


def _run(installed, argv, cwd, timeout=120):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "SHAREDCTL_STATE_DIR")}
    env["SHAREDCTL_STATE_DIR"] = str(installed["tmp"] / "state")
    return subprocess.run([str(installed["venv"] / "bin" / "sharedctl"), *argv], cwd=cwd, env=env,
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout)


def test_the_build_says_no_warning(installed):
    text = installed["build"].stdout + installed["build"].stderr
    assert "warning" not in text.lower(), [line for line in text.splitlines() if "warning" in line.lower()]


def test_the_wheel_holds_the_scenarios_the_dbc_the_license_and_the_entry_point(installed):
    names = set(zipfile.ZipFile(installed["wheel"]).namelist())
    assert {"sharedctl/scenarios/paper_convex.toml", "sharedctl/scenarios/paper_nonconvex.toml",
            "sharedctl/scenarios/adversarial_wall.toml", "sharedctl/protocol/odrive_cansimple.dbc",
            "sharedctl/services/console/gamepad_xbox.toml", "sharedctl/__main__.py"} <= names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    assert not any(n.startswith("tests/") for n in names)


def test_the_sdist_is_the_tracked_tree_so_its_tests_can_run(installed, tmp_path):
    """Before, the sdist held 19 of the 94 files under tests/ (and none of deploy/ or docs/ they read)."""
    import tarfile

    tree = installed["tmp"] / "src"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    script = f"import setuptools.build_meta as b; print(b.build_sdist({str(tmp_path)!r}))"
    built = subprocess.run([sys.executable, "-c", script], cwd=tree, capture_output=True, text=True, env=env,
                           timeout=300)
    assert built.returncode == 0, built.stderr[-2000:]
    assert "warning" not in (built.stdout + built.stderr).lower()
    with tarfile.open(tmp_path / built.stdout.split()[-1]) as sdist:
        members = {m.name.split("/", 1)[1] for m in sdist.getmembers() if m.isfile() and "/" in m.name}
    tracked = installed["files"]
    assert tracked - members == set()
    assert {m for m in members - tracked if not m.startswith("sharedctl.egg-info/")} <= {"PKG-INFO", "setup.cfg"}


def test_the_installed_package_is_the_wheels_not_the_source_tree(installed):
    where = subprocess.run([str(installed["python"]), "-P", "-c",
                            "import sharedctl.services.cli as c, sharedctl as s; print(c.__file__); print(s.__file__)"],
                           cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    assert all(str(installed["venv"]) in path for path in where), where


def test_version_and_python_dash_m(installed, tmp_path):
    version = _run(installed, ["--version"], tmp_path)
    assert version.returncode == 0 and version.stdout.strip() == "sharedctl 0.1.0", version
    helped = subprocess.run([str(installed["python"]), "-m", "sharedctl", "--help"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=120)
    assert helped.returncode == 0 and "demo" in helped.stdout and "router" in helped.stdout, helped.stderr


@pytest.mark.parametrize("where", ["clone_root", "elsewhere"])
@pytest.mark.parametrize("secure", [False, True], ids=["plain", "secure"])
def test_the_demo_runs_from_a_clones_root_and_from_anywhere(installed, tmp_path, where, secure):
    cwd = ROOT if where == "clone_root" else tmp_path
    out = tmp_path / "demo.json"
    argv = ["demo", "--headless", "--no-reference", "--scenario", "paper_convex.toml", "--duration", "1.5",
            "--feedback-timeout-ms", "150", "--json", str(out), "--log-dir", str(tmp_path / "logs")]
    proc = _run(installed, argv + (["--secure"] if secure else []), cwd)
    assert proc.returncode == 0, (proc.stderr[-3000:], sorted(p.name for p in (tmp_path / "logs").glob("*")))
    summary = json.loads(out.read_text())
    assert summary["violations"] == 0 and summary["failure"] is None
    assert (summary.get("security") is not None) == secure
