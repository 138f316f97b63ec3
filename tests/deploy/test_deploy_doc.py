"""docs/deploy.md names every file in deploy/, and every deploy/ path it names exists."""
import re

from .deploy_files import DEPLOY, DOC, ROOT


def test_the_walkthrough_names_every_file_in_deploy():
    doc = DOC.read_text()
    files = [p.relative_to(ROOT).as_posix() for p in DEPLOY.rglob("*") if p.is_file()]
    assert files
    missing = [f for f in files if f not in doc]
    assert not missing, f"docs/deploy.md does not mention {missing}"


def test_every_deploy_path_the_walkthrough_names_exists():
    named = set(re.findall(r"deploy/[A-Za-z0-9_./-]+[A-Za-z0-9_]", DOC.read_text()))
    absent = [p for p in sorted(named) if not (ROOT / p).exists() and "COMMAND" not in p]
    assert not absent, absent
