"""The demo's references (services/demo/reference_job.py): two processes, started when the run is over,
that return what measure.reference_run and measure.plant_reference_run return, and that a stop ends."""
import json
import subprocess
import sys
import threading

import pytest

from sharedctl.services.children import Child
from sharedctl.services.demo.measure import plant_reference_run, reference_run
from sharedctl.services.demo.reference_job import ReferenceJob
from sharedctl.services.lifecycle import StopFlag
from sharedctl.services.scenario_files import load

pytestmark = pytest.mark.processes
DURATION = 0.4


def test_the_two_parts_are_the_two_in_process_references(tmp_path):
    job = ReferenceJob("paper_convex", None, DURATION, tmp_path)
    assert len({child.popen.pid for child, _ in job.children.values()}) == 2   # side by side
    reference, plant = job.result(60.0, StopFlag())
    scenario = load("paper_convex")
    # through JSON, as the demo's summary holds them
    assert reference == json.loads(json.dumps(reference_run(scenario, None, DURATION)))
    assert plant == json.loads(json.dumps(plant_reference_run(scenario, None, DURATION)))


def test_a_stop_ends_both_parts_and_says_so(tmp_path):
    job = ReferenceJob("paper_nonconvex", None, 30.0, tmp_path)
    stop = StopFlag()
    threading.Timer(0.3, stop.stop).start()
    with pytest.raises(RuntimeError, match="interrupted"):
        job.result(60.0, stop)
    for child, _ in job.children.values():
        assert child.popen.poll() is not None


def test_a_part_that_fails_is_reported_with_its_log_and_the_other_is_stopped(tmp_path):
    job = ReferenceJob("paper_convex", "no-such-law", DURATION, tmp_path)
    plant, _ = job.children["plant"]
    plant.popen.wait(30.0)                               # fails too (the same law)
    # in its place, a part still running: the failure of the first must stop it, not leave it behind
    running = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"], start_new_session=True)
    try:
        job.children["plant"] = (Child("reference.plant", running, None), tmp_path / "never.json")
        with pytest.raises(RuntimeError, match=r"reference run failed \(exit [1-9].*reference\.reference\.log"):
            job.result(60.0, StopFlag())
        assert running.poll() is not None
    finally:
        if running.poll() is None:
            running.kill()
            running.wait()
