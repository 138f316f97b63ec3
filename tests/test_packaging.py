"""The three folders import as one namespace."""
import importlib


def test_folders_map_to_one_namespace():
    for name in ("sharedctl", "sharedctl.protocol", "sharedctl.services"):
        assert importlib.import_module(name).__doc__
