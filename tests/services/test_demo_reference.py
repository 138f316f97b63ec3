"""The demo's references (services/demo/reference_job.py): two processes, started when the run is over,
that return what measure.reference_run and measure.plant_reference_run return, and that a stop ends."""
import json
import threading

import pytest

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


def test_a_part_that_fails_is_reported_with_its_log(tmp_path):
    job = ReferenceJob("paper_convex", "no-such-law", DURATION, tmp_path)
    with pytest.raises(RuntimeError, match=r"reference run failed \(exit [1-9].*reference\.reference\.log"):
        job.result(60.0, StopFlag())
