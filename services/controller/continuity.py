"""What carries over from one controller's life to the next: the previous life's checkpoint, read at start, the
start decided from it (resume.py), and this life's checkpoints, written while it runs (checkpoint.py).

The daemon owns the modes; this object owns the files. `decide` is called once, when every axis has been heard
idle; `save` whenever the daemon wants a checkpoint written (the writer's thread writes it); `close` at the end.
"""
from __future__ import annotations

import time

from . import checkpoint as checkpoints
from . import resume
from .daemon_config import DaemonConfig


class Continuity:
    def __init__(self, config: DaemonConfig) -> None:
        self.config = config
        self.saved = self._read()                       # the previous life's checkpoint, None, or why not
        self.writer = (checkpoints.CheckpointWriter(config.checkpoint, config.checkpoint_interval)
                       if config.checkpoint is not None else None)
        self.boot_id = checkpoints.host_boot_id()
        self.failures_reported = 0

    def _read(self):
        if self.config.checkpoint is None:
            return None
        try:
            return checkpoints.read(self.config.checkpoint)
        except checkpoints.CheckpointError as exc:
            return exc

    @property
    def saved_estop_reason(self) -> str | None:
        """The reason of the Estop latched in the previous life's checkpoint, None if none was."""
        saved = self.saved
        return saved.reason if isinstance(saved, checkpoints.Checkpoint) and saved.estop else None

    def decide(self, q0, turns, errors) -> resume.Start:
        """The start (resume.py) from the previous life's checkpoint, the drives' readings and errors now."""
        saved, config = self.saved, self.config
        age = (saved.age(time.time(), time.monotonic(), self.boot_id)
               if isinstance(saved, checkpoints.Checkpoint) else None)
        return resume.decide(config.pose, saved, robot_id=config.robot_id, scenario=config.scenario, q0=q0,
                             turns=turns, errors=errors, age=age, max_age=config.checkpoint_max_age)

    def due(self, now: float) -> bool:
        return self.writer is not None and self.writer.due(now)

    def save(self, now: float, q, turns, theta_hat, *, estop: bool, reason: str, armed: bool,
             ended: bool = False) -> str | None:
        """Hand this checkpoint to the writer (`ended`: write it now, the last one); returns the text of a write
        failure not reported yet, else None."""
        writer = self.writer
        if writer is None:
            return None
        saved = checkpoints.Checkpoint(
            robot_id=self.config.robot_id, scenario=self.config.scenario, q=tuple(q), wheel_turns=tuple(turns),
            theta_hat=tuple(float(x) for x in theta_hat), estop=estop, reason=reason, wall=time.time(),
            monotonic=time.monotonic(), boot_id=self.boot_id, seq=writer.written + 1, ended=ended, armed=armed)
        if ended:
            writer.close(saved)             # the last one, written before the process exits
        else:
            writer.offer(saved, now)        # written by the writer's thread
        if writer.failures > self.failures_reported:
            self.failures_reported = writer.failures
            return f"checkpoint not written to {writer.path}: {writer.last_error} (a restart cannot resume)"
        return None

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()             # what was offered last is written too

    def summary(self) -> dict:
        writer = self.writer
        return {"checkpoints_written": 0 if writer is None else writer.written,
                "checkpoint_failures": 0 if writer is None else writer.failures}
