"""The import rules of the house (docs/services.md, "Layout"), checked on the source tree.

* `sharedctl/` (the control core) and `protocol/` (the wire contract) never import a service;
  the core never imports zenoh or python-can.
* No process (nor the core, nor the protocol) imports a study: studies (`services/studies/`) drive
  the processes, never the reverse.

Every `import` and `from … import` is read with `ast` (relative imports resolved against the
module's own package), including those inside functions — the per-command lazy imports too.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"sharedctl": "sharedctl", "protocol": "sharedctl.protocol", "services": "sharedctl.services"}
STUDIES = "sharedctl.services.studies"


def module_name(path: Path) -> str:
    folder = path.relative_to(ROOT).parts[0]
    parts = list(path.relative_to(ROOT / folder).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join([FOLDERS[folder], *parts])


def imported_modules(path: Path) -> set[str]:
    """Every module `path` imports (absolute names; `from X import y` counts as X and X.y)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.add(target)
            found.update(f"{target}.{alias.name}" for alias in node.names)
    return found


def sources(folder: str, exclude: str | None = None) -> list[Path]:
    paths = sorted((ROOT / folder).rglob("*.py"))
    return [p for p in paths if exclude is None or not p.is_relative_to(ROOT / exclude)]


def offenders(paths: list[Path], forbidden: tuple[str, ...]) -> dict[str, list[str]]:
    bad = {}
    for path in paths:
        hits = sorted(m for m in imported_modules(path) if any(m == f or m.startswith(f + ".") for f in forbidden))
        if hits:
            bad[str(path.relative_to(ROOT))] = hits
    return bad


def test_the_resolver_sees_a_relative_import_of_a_study(tmp_path, monkeypatch):
    """The oracle of the checks below can fail: a process module importing a study relatively is caught."""
    fake_root = tmp_path
    module = fake_root / "services" / "robot" / "spy.py"
    module.parent.mkdir(parents=True)
    module.write_text("def f():\n    from ..studies.bench import stack_run\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", fake_root)
    assert offenders([module], (STUDIES,)) == {"services/robot/spy.py": [STUDIES + ".bench",
                                                                         STUDIES + ".bench.stack_run"]}


ENTRY_POINT = ROOT / "sharedctl" / "__main__.py"    # `python -m sharedctl`: runs the command line, imported by nothing


@pytest.mark.parametrize("folder", ["sharedctl", "protocol"])
def test_the_core_and_the_protocol_import_no_service(folder):
    assert offenders([p for p in sources(folder) if p != ENTRY_POINT], ("sharedctl.services",)) == {}


def test_the_entry_point_imports_only_the_command_line_and_nothing_imports_it():
    assert offenders([ENTRY_POINT], ("sharedctl.services",)) == {"sharedctl/__main__.py": ["sharedctl.services.cli",
                                                                                           "sharedctl.services.cli.main"]}
    everything = [p for folder in FOLDERS for p in sources(folder)]
    assert offenders(everything, ("sharedctl.__main__",)) == {}


def test_the_control_core_imports_neither_zenoh_nor_python_can():
    assert offenders(sources("sharedctl"), ("zenoh", "can")) == {}


def test_no_process_imports_a_study():
    assert offenders(sources("services", exclude="services/studies"), (STUDIES,)) == {}


def test_every_study_command_is_registered_by_its_folder_name():
    """One folder per study; its `command.py` is the sub-command — the two fault studies are the actions
    of `faults`: `faults campaign` (registered as `faults`) and `faults montecarlo`."""
    from sharedctl.services.cli import COMMANDS, build_parser

    folders = sorted(p.parent.name for p in (ROOT / "services" / "studies").glob("*/command.py"))
    registered = {module.split(".")[3]: name for name, module in COMMANDS.items() if module.startswith(STUDIES + ".")}
    assert sorted(set(registered) | {"montecarlo"}) == folders
    assert all(name == folder for folder, name in registered.items() if folder != "campaign")
    assert registered["campaign"] == "faults"
    args = build_parser("faults").parse_args(["faults", "montecarlo", "--runs", "1"])
    assert args.handler.__module__ == STUDIES + ".montecarlo.command"
