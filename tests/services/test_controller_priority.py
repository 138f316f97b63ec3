"""CPU placement of the control loop (services/controller/priority.py): `--cpu N`.

Affinity is per thread on Linux, so each case runs in a thread of its own and the test process
keeps its CPUs. The nice of a process and of its session's autogroup: `raise_nice`, and the
launchers' `raise_priority` (services/children.py)."""
import contextlib
import os
import subprocess
import sys
import threading

import pytest

from sharedctl.services.children import raise_priority
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


# ----- nice on a kernel with autogroups: the session's group too (module doc) -----------------------
def _autogroups() -> bool:
    try:
        return open("/proc/sys/kernel/sched_autogroup_enabled").read().strip() == "1"
    except OSError:
        return False


def _group(pid) -> str:
    return open(f"/proc/{pid}/autogroup").read().strip()


needs_autogroups = pytest.mark.skipif(not _autogroups(), reason="this kernel has no autogroups "
                                      "(/proc/sys/kernel/sched_autogroup_enabled is not 1)")


def _may_lower_nice() -> bool:
    try:
        os.setpriority(os.PRIO_PROCESS, os.getpid(), os.getpriority(os.PRIO_PROCESS, os.getpid()))
        return os.geteuid() == 0
    except OSError:
        return False


@contextlib.contextmanager
def sleeping_child(**popen):
    """A `sleep` child of this test, killed and reaped at the end."""
    child = subprocess.Popen(["sleep", "30"], **popen)
    try:
        yield child
    finally:
        child.kill()
        child.wait()


@pytest.mark.processes
@needs_autogroups
@pytest.mark.skipif(not _may_lower_nice(), reason="lowering a nice value needs CAP_SYS_NICE (root here)")
def test_a_child_leading_its_own_session_gets_nice_minus_10_for_its_autogroup_too():
    with sleeping_child(start_new_session=True) as child:
        assert raise_priority(child.pid) == "nice -10 (its session's too)"
        assert os.getpriority(os.PRIO_PROCESS, child.pid) == -10
        assert _group(child.pid).endswith("nice -10")
        assert _group(os.getpid()) != _group(child.pid)          # the launcher's own group untouched


@pytest.mark.processes
@needs_autogroups
@pytest.mark.skipif(not _may_lower_nice(), reason="lowering a nice value needs CAP_SYS_NICE (root here)")
def test_a_child_in_the_launchers_session_leaves_that_sessions_group_as_it_was():
    before = _group(os.getpid())
    with sleeping_child() as child:
        assert raise_priority(child.pid) == "nice -10"
        assert os.getpriority(os.PRIO_PROCESS, child.pid) == -10
        assert _group(os.getpid()) == before == _group(child.pid)


@pytest.mark.processes
@needs_autogroups
@pytest.mark.skipif(not _may_lower_nice(), reason="lowering a nice value needs CAP_SYS_NICE (root here)")
def test_the_controllers_own_nice_reaches_its_sessions_group_when_it_leads_one():
    probe = ("import os; from sharedctl.services.controller.priority import raise_nice; print(raise_nice('high')); "
             "print(open('/proc/self/autogroup').read().strip())")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60,
                         start_new_session=True, check=True).stdout.splitlines()
    assert out[0] == "nice -10 (its session's too)" and out[1].endswith("nice -10"), out
