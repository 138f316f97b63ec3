"""The three folders import as one namespace; the locks in requirements/ pin what pyproject.toml ranges,
with hashes; the processes need nothing from an extra."""
import importlib
import json
import re
import subprocess
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
RUNTIME_LOCK = ROOT / "requirements" / "runtime.lock"
TEST_LOCK = ROOT / "requirements" / "test.lock"
LOCKS = (RUNTIME_LOCK, TEST_LOCK, ROOT / "requirements" / "tools.lock")


def locked(lock: Path) -> dict[str, tuple[str, frozenset[str]]]:
    """name -> (version, sha256 hashes) of every requirement in a hashed lock file."""
    entries = {}
    for block in re.split(r"\n(?=\S)", lock.read_text()):
        if block.startswith("#"):
            continue
        head = block.split("\\", 1)[0]
        name, sep, version = head.split(";", 1)[0].partition("==")
        assert sep, f"{lock.name}: not pinned with ==: {head.strip()}"
        hashes = frozenset(re.findall(r"--hash=sha256:([0-9a-f]{64})", block))
        entries[canonicalize_name(name.strip())] = (version.strip(), hashes)
    return entries


def extra_requirements() -> list[Requirement]:
    """Every requirement of every extra, the extras' references to the project itself left out."""
    reqs = [Requirement(r) for extra in PYPROJECT["project"]["optional-dependencies"].values() for r in extra]
    return [r for r in reqs if canonicalize_name(r.name) != canonicalize_name(PYPROJECT["project"]["name"])]


def test_folders_map_to_one_namespace():
    for name in ("sharedctl", "sharedctl.protocol", "sharedctl.services"):
        assert importlib.import_module(name).__doc__


@pytest.mark.parametrize("lock", LOCKS, ids=lambda p: p.name)
def test_every_locked_requirement_is_pinned_with_its_hashes(lock):
    entries = locked(lock)
    assert entries
    assert all(hashes for _, hashes in entries.values()), [n for n, (_, h) in entries.items() if not h]


def test_the_test_lock_pins_every_runtime_package_at_the_same_version_and_hashes():
    runtime, test = locked(RUNTIME_LOCK), locked(TEST_LOCK)
    assert {name: test.get(name) for name in runtime} == runtime


def test_the_runtime_lock_holds_no_package_that_only_an_extra_needs():
    runtime = locked(RUNTIME_LOCK)
    extras_only = {canonicalize_name(r.name) for r in extra_requirements()}
    assert extras_only and not extras_only & set(runtime)


@pytest.mark.parametrize("lock,requirements", [
    (RUNTIME_LOCK, lambda: PYPROJECT["project"]["dependencies"] + PYPROJECT["build-system"]["requires"]),
    (TEST_LOCK, lambda: [str(r) for r in extra_requirements()] + PYPROJECT["build-system"]["requires"]),
], ids=["runtime", "test"])
def test_each_lock_pins_every_range_of_pyproject_within_that_range(lock, requirements):
    entries = locked(lock)
    for text in requirements():
        req = Requirement(text)
        name = canonicalize_name(req.name)
        assert name in entries, f"{req.name} is not in {lock.name}"
        assert req.specifier.contains(entries[name][0], prereleases=True), f"{lock.name}: {req.name} {entries[name][0]}"


@pytest.mark.parametrize("lock", LOCKS, ids=lambda p: p.name)
def test_each_lock_starts_with_the_command_make_lock_regenerates_it_with(lock):
    header = lock.read_text().splitlines()[1]
    command = header.removeprefix("#").strip()
    recipe = [line.strip().replace("$(UV) ", "uv ", 1) for line in (ROOT / "Makefile").read_text().splitlines()
              if line.startswith("\t$(UV) pip compile")]
    assert command.startswith("uv pip compile") and command.endswith(f"-o {lock.relative_to(ROOT)}")
    assert command in recipe


def section(text: str, header: str) -> str:
    """The lines of one [table] of a TOML text, up to the next table header."""
    return text.split(f"\n{header}\n", 1)[1].split("\n[", 1)[0]


def test_every_dependency_in_pyproject_says_why_on_its_line():
    text = (ROOT / "pyproject.toml").read_text()
    tables = section(text, "[project]") + section(text, "[project.optional-dependencies]")
    lines = [line for line in tables.splitlines() if re.match(r'\s+"', line)]
    extras = PYPROJECT["project"]["optional-dependencies"].values()
    count = len(PYPROJECT["project"]["dependencies"]) + sum(map(len, extras))
    assert len(lines) == count
    assert all(re.search(r'",\s+# \S', line) for line in lines), [line for line in lines if "#" not in line]


# Processes that exist for an extra's sake: without it they stop with the message naming the extra.
PROCESS_EXTRAS = {"foxglove": "foxglove"}      # sharedctl foxglove, the live view (foxglove-sdk)

# The processes' command modules: everything outside services/studies/ (a study may import a process,
# never the reverse), found in the command table.
PROBE = """
import importlib, json, sys
blocked = json.loads(sys.argv[1])
for name in blocked:
    sys.modules[name] = None      # `import name` now raises ModuleNotFoundError
from sharedctl.services import cli
failed, extras = {}, {}
for command, module in cli.COMMANDS.items():
    if module.startswith("sharedctl.services.studies."):
        continue
    try:
        importlib.import_module(module)
        parser = cli.build_parser(command)
        if command in parser.unavailable:
            failed[command] = parser.unavailable[command]
    except ModuleNotFoundError as exc:
        if cli.missing_extra(exc):
            extras[command] = cli.missing_extra(exc)
        else:
            failed[command] = repr(exc)
    except ImportError as exc:
        failed[command] = repr(exc)
print(json.dumps({"failed": failed, "extras": extras}))
"""


@pytest.mark.processes     # a fresh interpreter, so no module imported by another test hides a missing one
def test_the_processes_import_nothing_that_only_the_test_lock_installs():
    runtime = set(locked(RUNTIME_LOCK))
    test_only = set(locked(TEST_LOCK)) - runtime
    blocked = sorted(module for module, dists in packages_distributions().items()
                     if dists and all(canonicalize_name(d) in test_only for d in dists))
    assert {"matplotlib", "quadprog", "pytest", "scipy", "yaml"} <= set(blocked)
    out = subprocess.run([sys.executable, "-c", PROBE, json.dumps(blocked)], capture_output=True, text=True,
                         timeout=120, check=True).stdout
    probed = json.loads(out)
    assert probed["failed"] == {}
    assert probed["extras"] == PROCESS_EXTRAS     # a process that is an extra's whole purpose, and only those
