"""The demo's in-process references (measure.reference_run, measure.plant_reference_run), computed
when the run is over, each in its own process.

The references depend only on the scenario, the law and the duration. They are not computed beside
the run: on a 2-core host the live processes (robot, controller, console) already take more than a
core, and a reference beside them, even at nice 19 or SCHED_IDLE, was measured to cost the robot a
quarter of its encoder frames and ten times the controller's missed ticks (the host's CPU is then
saturated, and a virtual machine's is rationed). So the demo starts them once its children have
stopped: `python -P -m sharedctl.services.demo.reference_job SCENARIO --duration S [--controller LAW]
--part reference|plant --json OUT`, the two parts in parallel, and reads both; on a failure or a
signal it stops them like any other child.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from sharedctl.services.children import Child, python_module

MODULE = "sharedctl.services.demo.reference_job"
PARTS = ("reference", "plant")


class ReferenceJob:
    """The references of one demo run: two processes, `reference` and `plant`, started together."""

    def __init__(self, scenario: str, controller: str | None, duration: float, log_dir: Path):
        self.children: dict[str, tuple[Child, Path]] = {}
        for part in PARTS:
            out = log_dir / f"reference.{part}.json"
            argv = [*python_module(MODULE), scenario, "--duration", repr(float(duration)), "--part", part,
                    "--json", str(out)]
            if controller:
                argv += ["--controller", controller]
            log = log_dir / f"reference.{part}.log"
            with open(log, "wb") as sink:
                popen = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=sink, stderr=subprocess.STDOUT,
                                         start_new_session=True)
            self.children[part] = Child(f"reference.{part}", popen, log), out

    def result(self, timeout: float, stop) -> tuple[dict, dict]:
        """(reference, reference_plant); RuntimeError if a part failed, did not finish within `timeout` s, or
        `stop` (a lifecycle.StopFlag: SIGTERM, SIGINT) was raised meanwhile; the parts are stopped then."""
        deadline = time.monotonic() + timeout
        results = []
        for child, out in self.children.values():
            while child.popen.poll() is None:
                if stop.stopped or time.monotonic() > deadline:
                    self.stop()
                    raise RuntimeError("interrupted" if stop.stopped else
                                       f"the reference run did not finish within {timeout:.0f} s")
                stop.wait(0.1)
            try:
                results.append(json.loads(out.read_text()))
            except (OSError, ValueError) as exc:
                self.stop()
                raise RuntimeError(f"the reference run failed (exit {child.popen.returncode}; "
                                   f"see {child.log}): {exc}") from None
        return results[0], results[1]

    def stop(self) -> None:
        for child, _ in self.children.values():
            if child.popen.poll() is None:
                child.stop()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m " + MODULE, description=__doc__.splitlines()[0])
    p.add_argument("scenario")
    p.add_argument("--duration", type=float, required=True)
    p.add_argument("--controller")
    p.add_argument("--part", choices=PARTS, required=True)
    p.add_argument("--json", required=True)
    args = p.parse_args(argv)
    from sharedctl.services.scenario_files import load

    from .measure import plant_reference_run, reference_run

    scenario = load(args.scenario)
    run = reference_run if args.part == "reference" else plant_reference_run
    out = run(scenario, args.controller, args.duration)
    tmp = Path(args.json + ".tmp")
    tmp.write_text(json.dumps(out))
    tmp.replace(args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
