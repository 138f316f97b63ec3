"""Every test gets a state folder of its own: a controller process started by a test keeps its checkpoint
there (services/controller/checkpoint.py), never beside another test's or the user's."""
import pytest


@pytest.fixture(autouse=True)
def _own_state_dir(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("SHAREDCTL_STATE_DIR", str(tmp_path_factory.mktemp("state")))
