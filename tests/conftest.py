"""Every test gets a state folder of its own: a controller process started by a test keeps its checkpoint
there (services/controller/checkpoint.py), never beside another test's or the user's. Every module of the
project is loaded before the first test, so that a property test's examples do not depend on the tests before it
(`_every_module_loaded`)."""
import importlib
import pkgutil

import pytest


@pytest.fixture(autouse=True)
def _own_state_dir(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("SHAREDCTL_STATE_DIR", str(tmp_path_factory.mktemp("state")))


@pytest.fixture(scope="session", autouse=True)
def _run_cache(tmp_path_factory):
    """A folder the test processes of this run share (helpers.packaged_run): this run's base folder, which the
    xdist workers have in common (each works in a folder of its own inside it); never one of another run."""
    import os

    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    os.environ["SHAREDCTL_TEST_RUN_CACHE"] = str(shared / "packaged-runs")
    yield
    os.environ.pop("SHAREDCTL_TEST_RUN_CACHE", None)


@pytest.fixture(scope="session", autouse=True)
def _every_module_loaded():
    """Hypothesis draws a share of its examples from the literals of the local modules loaded in the process (the
    project's; `hypothesis.internal.conjecture.providers._get_local_constants`), read again whenever a module has
    been loaded since. A test's examples, derandomized included, thus depended on what the tests before it in the
    same worker had imported — on the order of the files and on how xdist shared them out. With every module of
    the three packages loaded first, every test draws from the same literals in any worker and any order."""
    import sharedctl
    import sharedctl.protocol
    import sharedctl.services

    for package in (sharedctl, sharedctl.protocol, sharedctl.services):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            if info.name.rsplit(".", 1)[-1] != "__main__":      # `python -m sharedctl` would run the command line
                importlib.import_module(info.name)
