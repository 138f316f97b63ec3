"""The controller's checkpoint: where the robot was, what its wheel encoders read there, and whether an
Estop is latched — so that a controller started again after a failure resumes from the truth.

A controller that dies (a crash, `kill -9`, a hang ended by its supervisor) is restarted by systemd
(`Restart=on-failure`) or compose (`unless-stopped`). The new process knows nothing of the old one's
odometry; the scenario's start pose can be metres from where the robot is. While it runs, the
controller writes a checkpoint every `interval` seconds and at every Estop:

* the pose q and the wheel encoder readings (turns) that pose was integrated up to — one
  consistent pair, taken from the odometry in the same period;
* the adaptive estimate θ̂ (so the adaptation resumes where it was);
* whether an Estop is latched, and why; whether the drives were armed;
* when: wall time, the monotonic clock and the host's boot id (the age is taken on the monotonic
  clock when the boot is the same — a wall-clock step cannot make a checkpoint look fresh);
* `ended`: true only in the last checkpoint of a controller stopped on purpose (SIGTERM, SIGINT,
  `--duration`). A stop on purpose hands the robot back; only a controller that did not end
  this way is resumed.

The file is one line of JSON (a person can read it) with a CRC-32 of its contents, written
atomically: a temporary file beside it, then a rename, so a reader sees the old checkpoint or the
new one, never half of one. It is not fsync'ed: a checkpoint serves a process restart, which the
page cache survives; after a power loss the drives' encoders restart too, so the checkpoint's
readings would not match them anyway (`resume.py` refuses such a checkpoint).

Writing one costs a few hundred microseconds of file-system calls, a good part of a 2 ms period:
`CheckpointWriter` does it on a thread of its own, which holds the GIL only to encode (the calls
release it); the loop hands it the latest checkpoint and never waits.

No clock of its own (times are passed in), no bus.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
import threading
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path

VERSION = 1
DEFAULT_INTERVAL = 0.05    # s between checkpoints while running (and at every Estop)


class CheckpointError(ValueError):
    """A checkpoint file that exists but cannot be used: unreadable, corrupt, of another version or robot."""


@dataclass(frozen=True)
class Checkpoint:
    robot_id: str
    scenario: str
    q: tuple                    # pose (m, m, rad) at `wheel_turns`
    wheel_turns: tuple          # encoder positions (turns) per wheel, in node order
    theta_hat: tuple            # the adaptive estimate θ̂
    estop: bool                 # an Estop latched when this was written
    reason: str                 # why (the Estop's reason), "" if none
    wall: float                 # s, time.time() when written
    monotonic: float            # s, time.monotonic() when written
    boot_id: str                # the host's boot id ("" if unknown)
    seq: int                    # checkpoints written by this controller so far
    ended: bool = False         # the last checkpoint of a controller stopped on purpose
    armed: bool = False         # the drives were armed (RUNNING) when this was written

    def age(self, wall: float, monotonic: float, boot_id: str) -> float:
        """s since this was written: on the monotonic clock within one boot, else on the wall clock; +inf when
        that is negative (a clock stepped back) or not a number."""
        same_boot = bool(boot_id) and boot_id == self.boot_id
        age = monotonic - self.monotonic if same_boot else wall - self.wall
        return age if math.isfinite(age) and age >= 0.0 else math.inf


def host_boot_id() -> str:
    """The kernel's boot id (Linux), "" elsewhere."""
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return ""


def _canonical(body: dict) -> str:
    """The text the CRC covers: compact, keys sorted (JSON floats read back exactly, so a reader rebuilds it)."""
    return json.dumps(body, sort_keys=True, allow_nan=False, separators=(",", ":"))


def encode(checkpoint: Checkpoint) -> bytes:
    body = asdict(checkpoint)
    for key in ("q", "wheel_turns", "theta_hat"):
        body[key] = [float(x) for x in body[key]]
    text = _canonical(body)
    return f'{{"checkpoint":{text},"crc32":{zlib.crc32(text.encode())},"version":{VERSION}}}\n'.encode()


def decode(data: bytes) -> Checkpoint:
    """A checkpoint from its file's bytes; CheckpointError on anything but a whole, current, consistent one."""
    try:
        outer = json.loads(data)
        version, crc, body = outer["version"], outer["crc32"], outer["checkpoint"]
    except (ValueError, TypeError, KeyError) as exc:
        raise CheckpointError(f"not a checkpoint ({type(exc).__name__}: {exc})") from None
    if version != VERSION:
        raise CheckpointError(f"checkpoint version {version!r}, this controller reads {VERSION}")
    try:
        text = _canonical(body)
    except (ValueError, TypeError) as exc:
        raise CheckpointError(f"checkpoint body unreadable ({exc})") from None
    if zlib.crc32(text.encode()) != crc:
        raise CheckpointError("checkpoint CRC mismatch (corrupted)")
    try:
        checkpoint = Checkpoint(**{**body, **{k: tuple(float(x) for x in body[k])
                                              for k in ("q", "wheel_turns", "theta_hat")}})
    except (TypeError, ValueError, KeyError) as exc:
        raise CheckpointError(f"checkpoint fields wrong ({exc})") from None
    numbers = checkpoint.q + checkpoint.wheel_turns + checkpoint.theta_hat + (checkpoint.wall, checkpoint.monotonic)
    if not all(math.isfinite(x) for x in numbers):
        raise CheckpointError("checkpoint holds a non-finite number")
    return checkpoint


def read(path: str | Path) -> Checkpoint | None:
    """The checkpoint at `path`; None if there is no file; CheckpointError if there is one that cannot be used."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise CheckpointError(f"cannot read {path}: {exc}") from None
    return decode(data)


def write(path: str | Path, checkpoint: Checkpoint) -> None:
    """Atomically: a temporary file in the same folder, then a rename over `path` (OSError on failure)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(encode(checkpoint))
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def default_path(robot_id: str) -> Path:
    """Where a controller keeps its checkpoint unless told otherwise: $SHAREDCTL_STATE_DIR, else
    $XDG_STATE_HOME/sharedctl, else ~/.local/state/sharedctl; one file per robot."""
    folder = os.environ.get("SHAREDCTL_STATE_DIR")
    if not folder:
        base = os.environ.get("XDG_STATE_HOME") or os.path.join(os.path.expanduser("~"), ".local", "state")
        folder = os.path.join(base, "sharedctl")
    return Path(folder) / f"controller-{robot_id}.checkpoint"


class CheckpointWriter:
    """Writes the latest checkpoint offered, on its own thread (started at the first offer); a checkpoint
    offered while one is being written replaces any still waiting. Failures are counted, never raised."""

    def __init__(self, path: str | Path, interval: float = DEFAULT_INTERVAL) -> None:
        self.path, self.interval = Path(path), interval
        self.offered = self.written = self.failures = 0
        self.last_error = ""
        self.next_due = -math.inf
        self._cond = threading.Condition()
        self._pending: Checkpoint | None = None
        self._busy = self._closed = False
        self._thread: threading.Thread | None = None

    def due(self, now: float) -> bool:
        return now >= self.next_due

    def offer(self, checkpoint: Checkpoint, now: float) -> None:
        """Hand `checkpoint` to the writer thread (never waits); the next is due `interval` after `now`."""
        self.next_due = now + self.interval
        with self._cond:
            if self._closed:
                return
            self._pending = checkpoint
            self.offered += 1
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="checkpoint", daemon=True)
                self._thread.start()
            self._cond.notify()

    def flush(self, timeout: float = 2.0) -> bool:
        """Wait until what was offered is written (True) or `timeout` s (False)."""
        with self._cond:
            return self._cond.wait_for(lambda: self._pending is None and not self._busy, timeout)

    def close(self, last: Checkpoint | None = None, timeout: float = 2.0) -> None:
        """Flush, stop the thread, then write `last` (if any) on the calling thread."""
        self.flush(timeout)
        with self._cond:
            self._closed = True
            self._cond.notify()
        if self._thread is not None:
            self._thread.join(timeout)
        if last is not None:
            self._write(last)

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._pending is not None or self._closed)
                if self._pending is None:
                    return
                checkpoint, self._pending, self._busy = self._pending, None, True
            self._write(checkpoint)
            with self._cond:
                self._busy = False
                self._cond.notify_all()

    def _write(self, checkpoint: Checkpoint) -> None:
        try:
            write(self.path, checkpoint)
        except OSError as exc:
            self.failures += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            return
        self.written += 1
