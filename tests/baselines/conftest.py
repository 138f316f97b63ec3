"""Runs shared by the baseline tests (computed once per worker: each is a full 8 s scenario)."""
import functools

from sharedctl.baselines.comparison import build_strategy, run
from sharedctl.baselines.operator_link import IDEAL, IMPAIRED
from sharedctl.services.studies.compare.scenarios import adversarial_corner
from sharedctl.scenario import parse
from sharedctl.services.scenario_files import load

CONDITIONS = {"ideal": IDEAL, "impaired": IMPAIRED}


def scenario(name):
    return parse(adversarial_corner()) if name == "adversarial_corner" else load(name)


SHORT = 5.0   # s: the robot meets the face after ~2 s; the remaining 3 s it is pushed against it


def adversarial_run(strategy: str, condition: str = "ideal", name: str = "adversarial_wall", full: bool = False):
    """(loop, trace) of one strategy on an adversarial scenario: its full duration, or the first SHORT seconds."""
    return _run(strategy, condition, name, full)


@functools.lru_cache(maxsize=None)
def _run(strategy, condition, name, full):
    sc = scenario(name)
    loop, q0, v0 = sc.closed_loop()
    duration = sc.duration if full else min(SHORT, sc.duration)
    return loop, run(build_strategy(strategy, loop), loop, q0, v0, duration, CONDITIONS[condition])
