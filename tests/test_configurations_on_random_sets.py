"""The three configurations on random sets (issue "the paper's three configurations", Done when 1).

On random convex sets, random unions of polytopes and adversarial operators: every law stays
inside, the machine's samples are run by the configuration's own law (law_share ≥ 0.9), and the
NCE configuration's run differs from the CE one once the machine has acted — they share (12)'s
force, not the estimator, so identical runs would mean NCE's estimator never acted.
"""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sharedctl.metrics import summarize
from sharedctl.sharing import Authority

from . import strategies as S


def machine_acted(trace) -> bool:
    return bool(np.any(trace.authority != int(Authority.HUMAN)))


@settings(max_examples=4, **S.SIM_SETTINGS)
@given(case=st.one_of(S.convex_cases, S.union_cases, S.adversarial_cases))
def test_every_configuration_keeps_the_set_with_its_own_law_and_nce_differs_from_ce(case):
    traces = {law: S.run(case, law) for law in S.CONTROLLERS}
    for law, trace in traces.items():
        assert S.invariance_failure(case, law, trace) is None, S.describe(case, law, trace)
        summary = summarize(trace, S.case_dt(case))
        assert summary["violations"] == 0
        if machine_acted(trace):
            assert summary["law_share"] >= 0.9, (law, summary["law_share"], case.label)
    ce, nce = traces["ce"], traces["nce"]
    assert machine_acted(ce), f"{case.label} never brings the machine in: it would test nothing"
    first = int(np.flatnonzero(ce.authority != int(Authority.HUMAN))[0])
    assert not np.array_equal(ce.theta_hat[first:], nce.theta_hat[first:]), case.label
