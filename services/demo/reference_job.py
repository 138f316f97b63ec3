"""The demo's in-process references (measure.reference_run, measure.plant_reference_run), computed
while the run goes, in a process of the lowest CPU priority.

The references depend only on the scenario, the law and the duration, so the demo starts them with
its children instead of after the run: `python -P -m sharedctl.services.demo.reference_job SCENARIO
--duration S [--controller LAW] --json OUT`, niced to 19, so that it takes only the CPU the robot,
the controller and the console leave (CFS gives a nice-19 task about 1/70 of a nice-0 one's share
when they compete). The demo reads OUT when the run is over, waiting for it if it is not done; on a
failure or a signal it stops the job like any other child.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from sharedctl.services.children import Child, python_module

MODULE = "sharedctl.services.demo.reference_job"


class ReferenceJob:
    """The background reference of one demo run."""

    def __init__(self, scenario: str, controller: str | None, duration: float, log_dir: Path):
        self.out = log_dir / "reference.json"
        argv = [*python_module(MODULE), scenario, "--duration", repr(float(duration)), "--json", str(self.out)]
        if controller:
            argv += ["--controller", controller]
        log = log_dir / "reference.log"
        with open(log, "wb") as sink:
            popen = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=sink, stderr=subprocess.STDOUT,
                                     start_new_session=True, preexec_fn=_lowest_priority)
        self.child = Child("reference", popen, log)

    def result(self, timeout: float) -> tuple[dict, dict]:
        """(reference, reference_plant); RuntimeError if the job failed or did not finish within `timeout` s."""
        try:
            self.child.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.stop()
            raise RuntimeError(f"the reference run did not finish within {timeout:.0f} s") from None
        try:
            data = json.loads(self.out.read_text())
            return data["reference"], data["reference_plant"]
        except (OSError, ValueError, KeyError) as exc:
            raise RuntimeError(f"the reference run failed (exit {self.child.popen.returncode}; "
                               f"see {self.child.log}): {exc}") from None

    def stop(self) -> None:
        if self.child.popen.poll() is None:
            self.child.stop()


def _lowest_priority() -> None:
    os.nice(19)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m " + MODULE, description=__doc__.splitlines()[0])
    p.add_argument("scenario")
    p.add_argument("--duration", type=float, required=True)
    p.add_argument("--controller")
    p.add_argument("--json", required=True)
    args = p.parse_args(argv)
    from sharedctl.services.scenario_files import load

    from .measure import plant_reference_run, reference_run

    scenario = load(args.scenario)
    out = {"reference": reference_run(scenario, args.controller, args.duration),
           "reference_plant": plant_reference_run(scenario, args.controller, args.duration)}
    tmp = Path(args.json + ".tmp")
    tmp.write_text(json.dumps(out))
    tmp.replace(args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
