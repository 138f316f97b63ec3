"""The Monte-Carlo's executor (services/studies/montecarlo/executor.py): the split of the runs into chunks,
the seeding of a chunk's task, and the run of the chunks on Dask — an in-process LocalCluster of 1 or 2
workers, and a scheduler with two workers started here by hand — all giving the results the task gives
called serially here, in chunk order.

The tests that start a cluster are marked `processes`. Their tasks are this file's functions, which Dask
pickles by reference as the study's own task: the workers import this file, from its import root (the
folder pytest imports it from) put on their sys.path."""
from __future__ import annotations

import importlib
import os
import signal
import socket
import ssl
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from sharedctl.services.studies.montecarlo import executor
from sharedctl.services.studies.montecarlo.executor import CHUNK_RUNS, Chunk, chunk_rng, plan_chunks, run_chunks
from sharedctl.services.zenoh_session import free_loopback_port

# pytest imports this file as `studies.test_montecarlo_executor`: the folder that name is relative to.
IMPORT_ROOT = Path(__file__).resolve().parents[__name__.count(".")]

RUNS, SEED = 1000, 20240611        # 4 chunks of 256, 256, 256 and 232 runs
SPLIT = 256                        # runs per chunk in these tests


def uniform_draws(chunk: Chunk) -> np.ndarray:
    """The demo task: one uniform draw per run, seeded the one way a chunk's task seeds itself."""
    return chunk_rng(chunk).random(chunk.runs)


def serial_results(chunks: list[Chunk]) -> list[np.ndarray]:
    return [uniform_draws(c) for c in chunks]


def assert_same_results(got: list[np.ndarray], expected: list[np.ndarray]) -> None:
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        np.testing.assert_array_equal(a, b)


# --- the split and the seeding (pure) -----------------------------------------------------------------------

@pytest.mark.parametrize("runs,chunk_runs", [(1, 256), (255, 256), (256, 256), (257, 256), (1000, 256), (10, 3)])
def test_the_chunks_cover_every_run_exactly_once_in_order(runs, chunk_runs):
    chunks = plan_chunks(runs, SEED, chunk_runs)
    covered = [run for c in chunks for run in range(c.first_run, c.first_run + c.runs)]
    assert covered == list(range(runs))
    assert [c.index for c in chunks] == list(range(len(chunks)))
    assert all(c.runs == chunk_runs for c in chunks[:-1]) and 1 <= chunks[-1].runs <= chunk_runs


def test_the_split_is_a_function_of_the_runs_and_the_seed_alone():
    assert plan_chunks(RUNS, SEED) == plan_chunks(RUNS, SEED, CHUNK_RUNS)
    chunks = plan_chunks(RUNS, SEED, SPLIT)
    assert [(c.first_run, c.runs) for c in chunks] == [(0, 256), (256, 256), (512, 256), (768, 232)]
    assert {c.seed for c in chunks} == {SEED}


@pytest.mark.parametrize("runs,seed,chunk_runs", [(0, 1, 256), (10, -1, 256), (10, 1, 0)])
def test_a_split_of_no_run_a_negative_seed_or_empty_chunks_is_refused(runs, seed, chunk_runs):
    with pytest.raises(ValueError):
        plan_chunks(runs, seed, chunk_runs)


def test_a_chunk_draws_the_stream_of_the_seeds_child_of_its_index():
    """numpy's documented independent streams: child i of SeedSequence(seed).spawn(n)."""
    chunks = plan_chunks(RUNS, SEED, SPLIT)
    children = np.random.SeedSequence(SEED).spawn(len(chunks))
    for chunk, child in zip(chunks, children):
        np.testing.assert_array_equal(chunk_rng(chunk).random(5), np.random.default_rng(child).random(5))
    assert len({float(chunk_rng(c).random()) for c in chunks}) == len(chunks)


@pytest.mark.parametrize("address", ["127.0.0.1:8786", "http://127.0.0.1:8786", "inproc://127.0.0.1:8786",
                                     "tcp://127.0.0.1", "tcp://:8786", "tcp://127.0.0.1:port", ""])
def test_a_scheduler_address_that_is_not_tcp_or_tls_host_port_is_refused(address):
    with pytest.raises(ValueError, match="tcp://HOST:PORT"):
        run_chunks(uniform_draws, plan_chunks(RUNS, SEED, SPLIT), scheduler=address)


def test_a_worker_count_with_a_scheduler_is_refused():
    with pytest.raises(ValueError, match="workers"):
        run_chunks(uniform_draws, plan_chunks(RUNS, SEED, SPLIT), scheduler="tcp://127.0.0.1:8786", workers=2)


def test_without_dask_the_run_names_the_extra_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ModuleNotFoundError, match=r"pip install 'sharedctl\[montecarlo\]'") as caught:
        run_chunks(uniform_draws, plan_chunks(RUNS, SEED, SPLIT))
    assert caught.value.name == "distributed"


# --- an in-process LocalCluster -----------------------------------------------------------------------------

def worker_processes() -> set[int]:
    """The PIDs of this process's children that are multiprocessing workers (not its resource tracker)."""
    return {p.pid for p in psutil.Process().children(recursive=True)
            if "resource_tracker" not in " ".join(_cmdline(p))}


def _cmdline(process: psutil.Process) -> list[str]:
    try:
        return process.cmdline()
    except psutil.Error:
        return []


@pytest.fixture
def reap_workers(monkeypatch):
    """Lets the workers import this file; after the test, kills (by PID) any worker process started during it
    and still alive. Yields a function that says which ones are alive now."""
    assert (IMPORT_ROOT / Path(*__name__.split("."))).with_suffix(".py") == Path(__file__).resolve()
    monkeypatch.syspath_prepend(str(IMPORT_ROOT))     # a LocalCluster's workers start with this sys.path
    before = worker_processes()
    yield lambda: worker_processes() - before
    for pid in worker_processes() - before:
        with _suppress_gone():
            psutil.Process(pid).kill()


class _suppress_gone:
    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        return kind is not None and issubclass(kind, (psutil.NoSuchProcess, ProcessLookupError))


@pytest.mark.processes
@pytest.mark.parametrize("workers", [1, 2])
def test_a_local_cluster_returns_what_the_task_returns_serially_whatever_the_workers(workers, reap_workers):
    chunks = plan_chunks(RUNS, SEED, SPLIT)
    results, info = run_chunks(uniform_draws, chunks, workers=workers)
    assert_same_results(results, serial_results(chunks))
    assert info.workers == workers
    assert 0 < info.startup_seconds <= info.wall_seconds
    assert reap_workers() == set()


def slow_first_chunk(chunk: Chunk) -> int:
    time.sleep(0.5 if chunk.index == 0 else 0.0)
    return chunk.index


@pytest.mark.processes
def test_on_result_fires_once_per_chunk_as_it_finishes_and_the_results_keep_chunk_order(reap_workers):
    chunks = plan_chunks(RUNS, SEED, SPLIT)
    calls = []

    def record(chunk, result, done, total):
        calls.append((chunk.index, result, done, total))

    results, _ = run_chunks(slow_first_chunk, chunks, workers=2, on_result=record)
    assert results == [0, 1, 2, 3]
    assert sorted(index for index, _, _, _ in calls) == [0, 1, 2, 3]
    assert [(done, total) for _, _, done, total in calls] == [(1, 4), (2, 4), (3, 4), (4, 4)]
    assert all(index == result for index, result, _, _ in calls)
    assert calls[0][0] != 0, "chunk 0 sleeps 0.5 s while the other worker finishes a chunk at once"


def environment_of_the_worker(chunk: Chunk) -> dict:
    return {name: os.environ.get(name) for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


@pytest.mark.processes
def test_the_local_workers_run_numpy_single_threaded_and_the_callers_environment_is_left_as_it_was(
        monkeypatch, reap_workers):
    import dask

    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "PYTHONHASHSEED"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "12345")
    before = dict(os.environ)
    overridden = {"distributed.nanny.pre-spawn-environ.OMP_NUM_THREADS": 4}   # what a user's dask config might say
    with dask.config.set(overridden):
        results, _ = run_chunks(environment_of_the_worker, plan_chunks(600, SEED, SPLIT), workers=2)
    assert results == [{"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}] * 3
    assert dict(os.environ) == before


def listening_sockets(process: psutil.Process) -> set[tuple[str, int]]:
    with _suppress_gone():
        return {(c.laddr.ip, c.laddr.port) for c in process.net_connections("inet") if c.status == psutil.CONN_LISTEN}
    return set()


@pytest.mark.processes
def test_the_local_cluster_listens_on_the_loopback_only(reap_workers):
    me = psutil.Process()
    before = listening_sockets(me)
    seen: set[tuple[str, int]] = set()

    def look(chunk, result, done, total):
        seen.update(listening_sockets(me) - before)
        for child in me.children(recursive=True):
            seen.update(listening_sockets(child))

    run_chunks(uniform_draws, plan_chunks(600, SEED, SPLIT), workers=2, on_result=look)
    assert seen, "the cluster listens somewhere"
    assert {ip for ip, _ in seen} == {"127.0.0.1"}, seen
    assert 8787 not in {port for _, port in seen}, "the well-known dashboard port is left free"


@pytest.mark.processes
def test_the_local_scheduler_refuses_a_client_without_the_clusters_certificate(reap_workers):
    import distributed

    with executor._local_cluster(distributed, 1) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://127.0.0.1:")
        host, port = address.removeprefix("tls://").rsplit(":", 1)
        outsider = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)        # trusts anything, shows no certificate
        outsider.check_hostname, outsider.verify_mode = False, ssl.CERT_NONE
        with socket.create_connection((host, int(port)), timeout=5) as raw:
            with pytest.raises((ssl.SSLError, ConnectionError)):
                with outsider.wrap_socket(raw) as tls:
                    tls.sendall(b"\0" * 8)
                    if not tls.recv(1):
                        raise ConnectionResetError("the scheduler closed the connection")


def scratch_of_the_worker(chunk: Chunk) -> str:
    from distributed import get_worker

    return get_worker().local_directory


@pytest.mark.processes
def test_the_local_workers_scratch_space_is_private_and_removed_at_the_end(reap_workers):
    (directory,), _ = run_chunks(scratch_of_the_worker, plan_chunks(10, SEED, SPLIT), workers=1)
    shared = Path(tempfile.gettempdir()) / "dask-scratch-space"
    assert not Path(directory).is_relative_to(shared), directory
    private = next(p for p in Path(directory).parents if p.name.startswith("sharedctl-montecarlo-"))
    assert not private.exists()


@pytest.mark.processes
def test_a_task_the_workers_cannot_import_fails_the_run_instead_of_leaving_it_waiting(tmp_path, reap_workers):
    """Dask itself would wait for ever: the worker that cannot unpickle a task drops its scheduler stream."""
    (tmp_path / "montecarlo_elsewhere.py").write_text("def task(chunk):\n    return chunk.index\n")
    sys.path.insert(0, str(tmp_path))
    try:
        task = importlib.import_module("montecarlo_elsewhere").task
    finally:
        sys.path.remove(str(tmp_path))      # importable here, not in the workers this run spawns
    outcome = {}

    def run():
        try:
            outcome["results"] = run_chunks(task, plan_chunks(RUNS, SEED, SPLIT), workers=1)
        except BaseException as exc:  # noqa: BLE001 - handed to the test's thread, which asserts on it
            outcome["error"] = exc

    try:
        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        thread.join(timeout=60)
        assert not thread.is_alive(), "the run still waits after 60 s"
    finally:
        sys.modules.pop("montecarlo_elsewhere", None)
    assert isinstance(outcome.get("error"), RuntimeError), outcome
    assert "cannot load the task montecarlo_elsewhere.task" in str(outcome["error"])
    assert "No module named 'montecarlo_elsewhere'" in str(outcome["error"])


def fails_on_chunk_one(chunk: Chunk) -> int:
    if chunk.index == 1:
        raise ArithmeticError("chunk 1 failed")
    return chunk.index


@pytest.mark.processes
def test_a_tasks_exception_is_raised_to_the_caller_and_the_cluster_is_closed(reap_workers):
    with pytest.raises(ArithmeticError, match="chunk 1 failed"):
        run_chunks(fails_on_chunk_one, plan_chunks(RUNS, SEED, SPLIT), workers=2)
    assert reap_workers() == set()


@pytest.mark.processes
def test_an_interrupt_closes_the_cluster(reap_workers):
    def interrupt(chunk, result, done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_chunks(slow_first_chunk, plan_chunks(RUNS, SEED, SPLIT), workers=2, on_result=interrupt)
    assert reap_workers() == set()


# --- a scheduler and two workers started by hand ------------------------------------------------------------

def _start(argv: list[str], log, scratch: Path) -> subprocess.Popen:
    """`python -m ARGV` of this venv; it can import this file (PYTHONPATH: its import root), and keeps its
    scratch space in `scratch`."""
    path = os.pathsep.join(filter(None, [str(IMPORT_ROOT), os.environ.get("PYTHONPATH")]))
    env = dict(os.environ, PYTHONPATH=path, DASK_TEMPORARY_DIRECTORY=str(scratch))
    return subprocess.Popen([sys.executable, "-m", *argv], stdout=log, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, env=env)


def _reap(processes: list[subprocess.Popen]) -> None:
    """SIGTERM the workers, then the scheduler (a worker whose scheduler is gone takes ~9 s to close), each
    waited for, SIGKILL what is left — the started processes and every descendant they had (a nanny's worker
    process), by PID."""
    descendants = []
    for proc in processes:
        with _suppress_gone():
            descendants += psutil.Process(proc.pid).children(recursive=True)
    for group in (processes[1:], processes[:1]):
        for proc in group:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in group:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)
    for child in descendants:
        with _suppress_gone():
            child.kill()
            child.wait(timeout=10)


@pytest.fixture
def hand_started_cluster(tmp_path):
    """`dask scheduler` and two `dask worker`s (one thread each), every socket on 127.0.0.1, no dashboard (the
    HTTP servers they open anyway on a free loopback port: the CLI defaults bind every interface); yields the
    scheduler's address and the started processes once the scheduler has both workers."""
    import distributed

    port = free_loopback_port()
    address = f"tcp://127.0.0.1:{port}"
    processes = []
    try:
        with open(tmp_path / "scheduler.log", "wb") as log:
            processes.append(_start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(port),
                                     "--no-dashboard", "--dashboard-address", "127.0.0.1:0",
                                     "--idle-timeout", "120"], log, tmp_path))
        for i in range(2):
            with open(tmp_path / f"worker{i}.log", "wb") as log:
                processes.append(_start(["distributed.cli.dask_worker", address, "--nthreads", "1", "--nworkers", "1",
                                         "--host", "127.0.0.1", "--no-dashboard", "--dashboard-address",
                                         "127.0.0.1:0", "--death-timeout", "30"], log, tmp_path))
        with distributed.Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=30)
        yield address, processes
    finally:
        _reap(processes)
        assert all(p.returncode is not None for p in processes)


@pytest.mark.processes
def test_a_hand_started_scheduler_with_two_workers_gives_the_in_process_results(hand_started_cluster):
    address, processes = hand_started_cluster
    chunks = plan_chunks(RUNS, SEED, SPLIT)
    calls = []
    results, info = run_chunks(uniform_draws, chunks, scheduler=address,
                               on_result=lambda chunk, result, done, total: calls.append(chunk.index))
    assert_same_results(results, serial_results(chunks))
    assert info.workers == 2
    assert sorted(calls) == [0, 1, 2, 3]
    for proc in processes:
        parent = psutil.Process(proc.pid)
        sockets = set().union(*(listening_sockets(p) for p in (parent, *parent.children(recursive=True))))
        assert sockets and {ip for ip, _ in sockets} == {"127.0.0.1"}, (parent.cmdline(), sockets)
