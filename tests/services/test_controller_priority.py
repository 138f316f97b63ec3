"""CPU placement of the control loop (services/controller/priority.py): `--cpu N`.

Affinity is per thread on Linux, so each case runs in a thread of its own and the test process
keeps its CPUs."""
import os
import threading

import pytest

from sharedctl.services.controller.priority import keep_off_cpu, pin_to_cpu


def in_a_thread(body):
    result = {}

    def run():
        try:
            result["value"] = body()
        except Exception as exc:  # noqa: BLE001 — handed back to the test
            result["error"] = exc

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    if "error" in result:
        raise result["error"]
    return result["value"]


def test_the_loop_thread_is_pinned_to_its_cpu_alone():
    cpu = max(os.sched_getaffinity(0))
    assert in_a_thread(lambda: (pin_to_cpu(cpu), os.sched_getaffinity(0))) == (True, {cpu})
    assert cpu in os.sched_getaffinity(0)         # the test's own thread is untouched


def test_other_threads_are_kept_off_the_loop_cpu_when_another_is_allowed():
    allowed = os.sched_getaffinity(0)
    cpu = max(allowed)
    text, after = in_a_thread(lambda: (keep_off_cpu(cpu), os.sched_getaffinity(0)))
    if len(allowed) > 1:
        assert after == allowed - {cpu} and text.startswith("other threads on CPUs")
    else:
        assert after == allowed and "only one" in text


def test_a_cpu_the_process_may_not_use_is_refused():
    missing = max(os.sched_getaffinity(0)) + 1
    with pytest.raises(ValueError, match="not among"):
        in_a_thread(lambda: keep_off_cpu(missing))
    assert in_a_thread(lambda: pin_to_cpu(missing)) is False
