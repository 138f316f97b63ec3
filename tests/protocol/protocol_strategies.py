"""Hypothesis strategies for valid protocol values (shared by the protocol tests)."""
from __future__ import annotations

from hypothesis import strategies as st

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol import messages as m
from sharedctl.protocol.odrive_enums import ODriveError
from sharedctl.protocol.wire_types import MAX_TEXT_LEN, ROBOT_DIMS, TOKEN_PATTERN, Dims

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


# --- Zenoh messages -------------------------------------------------------------------------------

finite = st.floats(allow_nan=False, allow_infinity=False)
unit_interval = st.floats(min_value=0.0, max_value=1.0)
non_negative = st.floats(min_value=0.0, allow_infinity=False)
uint64s = st.integers(0, 2**64 - 1)
tokens = st.from_regex(TOKEN_PATTERN, fullmatch=True)
texts = st.text(st.characters(codec="utf-8", exclude_categories=("Cc", "Cs")) | st.sampled_from("\t\n"),
                max_size=MAX_TEXT_LEN)
dims_strategy = st.builds(Dims, st.integers(1, 8), st.integers(0, 16), st.integers(1, 8))


def vectors(n: int, elements: st.SearchStrategy = finite) -> st.SearchStrategy:
    return st.lists(elements, min_size=n, max_size=n).map(tuple)


def operator_commands(dims: Dims = ROBOT_DIMS) -> st.SearchStrategy:
    n = dims.dof
    return st.builds(
        m.OperatorCommand, operator_id=tokens, session_id=tokens, seq=uint64s, send_time=non_negative,
        joystick=vectors(n, st.floats(-1.0, 1.0)), q_d=vectors(n), qd_d=vectors(n), qdd_d=vectors(n),
        deadman=st.booleans(), estop=st.booleans(), control_request=st.sampled_from(m.ControlRequest))


link_healths = st.builds(m.LinkHealth, non_negative, unit_interval, non_negative, non_negative)


@st.composite
def robot_states(draw, dims: Dims = ROBOT_DIMS):
    n = dims.dof
    groups = draw(st.lists(st.sampled_from(m.SetClass), max_size=16).map(tuple))
    active = draw(st.none() | st.integers(0, len(groups) - 1)) if groups else None
    return m.RobotState(
        seq=draw(uint64s), time=draw(non_negative), q=draw(vectors(n)), qd_hat=draw(vectors(n)),
        q_ref=draw(vectors(n)), group_classes=groups, active_group=active,
        authority=draw(st.sampled_from(m.Authority)), k_s=draw(unit_interval), k_h=draw(unit_interval),
        k_f=draw(unit_interval), u_h=draw(vectors(n)), u_f=draw(vectors(n)), u_s=draw(vectors(n)),
        wheel_torques=draw(vectors(dims.n_wheels)), theta_hat=draw(vectors(dims.n_theta)),
        min_margin=draw(finite), region_margins=draw(st.lists(finite, max_size=32).map(tuple)),
        estop_active=draw(st.booleans()), lease_holder=draw(st.none() | tokens), link=draw(link_healths))


events = st.builds(m.Event, seq=uint64s, time=non_negative, kind=st.sampled_from(m.EventKind),
                   severity=st.sampled_from(m.Severity), source=tokens, text=texts)
heartbeats = st.builds(m.Heartbeat, role=tokens, id=tokens, seq=uint64s, time=non_negative)
lease_requests = st.builds(m.LeaseRequest, operator_id=tokens, session_id=tokens, seq=uint64s,
                           time=non_negative, action=st.sampled_from(m.LeaseAction))
lease_replies = st.builds(m.LeaseReply, request_seq=uint64s, time=non_negative, granted=st.booleans(),
                          holder=st.none() | tokens, reason=texts)


def ground_truths(dims: Dims = ROBOT_DIMS) -> st.SearchStrategy:
    return st.builds(m.GroundTruth, seq=uint64s, time=non_negative, q=vectors(dims.dof), qd=vectors(dims.dof))


def messages_of(cls: type, dims: Dims = ROBOT_DIMS) -> st.SearchStrategy:
    """Valid messages of one type with the given dimensions."""
    return {
        m.OperatorCommand: lambda: operator_commands(dims),
        m.RobotState: lambda: robot_states(dims),
        m.Event: lambda: events,
        m.Heartbeat: lambda: heartbeats,
        m.LeaseRequest: lambda: lease_requests,
        m.LeaseReply: lambda: lease_replies,
        m.GroundTruth: lambda: ground_truths(dims),
    }[cls]()


any_message = st.one_of([messages_of(cls) for cls in m.MESSAGE_TYPES])

# arbitrary MessagePack-representable values, for structure-aware mutation
msgpack_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats() | st.text(max_size=20)
    | st.binary(max_size=20),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner, max_size=5),
    max_leaves=12,
)
