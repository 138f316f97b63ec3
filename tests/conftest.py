"""Every test gets a state folder of its own: a controller process started by a test keeps its checkpoint
there (services/controller/checkpoint.py), never beside another test's or the user's."""
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
