"""Hypothesis strategies for valid protocol values (shared by the protocol tests)."""
from __future__ import annotations

from hypothesis import strategies as st

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.odrive_enums import ODriveError

node_ids = st.integers(min_value=0, max_value=63)
float32s = st.floats(width=32, allow_nan=False, allow_infinity=False)


def _signal_values(sig: cs.SignalSpec) -> st.SearchStrategy:
    if sig.kind == "float":
        return st.floats(min_value=sig.minimum, width=32, allow_nan=False, allow_infinity=False)
    if sig.kind == "bool":
        return st.booleans()
    if sig.kind == "flag":
        return st.integers(0, 2**32 - 1).map(ODriveError)
    return st.sampled_from(list(sig.enum))


def frames_of(cls: type, nodes: st.SearchStrategy = node_ids) -> st.SearchStrategy:
    """Valid typed CANSimple frames of one class."""
    if cls is cs.PollRequest:
        return st.builds(
            cs.PollRequest,
            nodes,
            st.sampled_from(sorted(cs.POLLABLE_COMMANDS)),
            st.sampled_from([0, 8]),
        )
    spec = cs.FRAME_SPECS[cls]
    return st.builds(cls, nodes, *(_signal_values(sig) for sig in spec.signals))


data_frame_classes = list(cs.FRAME_SPECS)
can_messages = st.one_of([frames_of(cls) for cls in [*data_frame_classes, cs.PollRequest]])
