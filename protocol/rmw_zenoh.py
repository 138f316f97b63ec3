"""rmw_zenoh's wire conventions, so that ROS 2 (Jazzy, `RMW_IMPLEMENTATION=rmw_zenoh_cpp`) sees our topics. Pure.

What `ros2 topic list/echo/pub` over rmw_zenoh expects, from rmw_zenoh's design document
(ros2/rmw_zenoh, docs/design.md: "Topic and Service name mapping to Zenoh key expressions",
"Graph Cache", "Publishers") and the code it names (`liveliness_utils.cpp`: `qos_to_keyexpr`,
`mangle_name`; `qos.cpp`: the default QoS):

* **Topic key expression** — ``<domain_id>/<fully qualified name without its leading '/'>/<type
  name as in DDS>/<type hash>``, e.g. ``0/robot1/chatter/std_msgs::msg::dds_::String_/RIHS01_df66…``
  (`topic_key`).
* **Liveliness tokens** — one per node and one per publisher/subscription, for as long as it exists:

      @ros2_lv/<domain_id>/<session_id>/<node_id>/<node_id>/NN/<enclave>/<namespace>/<node_name>
      @ros2_lv/<domain_id>/<session_id>/<node_id>/<entity_id>/<MP|MS>/<enclave>/<namespace>/<node_name>/
          <qualified name>/<type name>/<type hash>/<qos>

  where a name is *mangled* (each '/' replaced by '%'; the default enclave and namespace '/'
  become '%'), `session_id` is the Zenoh session id as Zenoh prints it, and `<qos>` is
  ``<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<s>,<ns>``
  with every value equal to rmw_zenoh's default left empty (reliable, volatile, keep-last, depth 42,
  infinite durations, automatic liveliness): depth 10 and nothing else is ``::,10:,:,:,,``
  (`node_token`, `entity_token`, `Qos.keyexpr`).
* **Publication attachment** — every sample carries 33 bytes: the sequence number (int64
  little-endian), the source timestamp (int64 little-endian, ns since the UNIX epoch), the
  GID's length (one byte, 16) and the publisher's GID (16 bytes) (`Attachment`). This is
  zenoh's own serialisation of (int64, int64, uint8[16]) (`zenoh.ext.z_serialize`).
* **Types and hashes** — pinned to ROS 2 **Jazzy**: the type name in DDS form
  (``nav_msgs::msg::dds_::Odometry_``, `dds_type_name`) and the REP-2011 type hash (RIHS01)
  of each type used here (`TYPE_HASHES`; the same as rosbags' Jazzy typestore computes, and
  std_msgs/msg/String's is the one the design document prints).

The GID (`gid_of`): as rmw_zenoh's `Entity` makes it, XXH3-128 (seed 0) of the entity's whole
liveliness token, its low 64 bits then its high 64 bits, each little-endian — the GID `ros2 topic
info -v` prints for the same token. XXH3 comes from the `xxhash` package (the `ros2` extra).
"""
from __future__ import annotations

import enum
import re
import struct
from dataclasses import dataclass

from .errors import BadAttachment, KeyExprError

DISTRO = "jazzy"
ADMIN_SPACE = "@ros2_lv"
SLASH_REPLACEMENT = "%"

# RIHS01 type hashes of ROS 2 Jazzy (REP-2011), checked against rosbags' Jazzy typestore
# (`hash_rihs01`) by tests/protocol/test_rmw_zenoh.py; std_msgs/msg/String's is the design document's.
TYPE_HASHES: dict[str, str] = {
    "nav_msgs/msg/Odometry": "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "geometry_msgs/msg/Twist": "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    "std_msgs/msg/String": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
}

GID_SIZE = 16
_ATTACHMENT = struct.Struct("<qqB16s")        # seq, source timestamp (ns), GID length, GID
ATTACHMENT_SIZE = _ATTACHMENT.size            # 33
_INT64 = (-(1 << 63), (1 << 63) - 1)
MAX_DOMAIN_ID = 232                           # ROS 2's range of ROS_DOMAIN_ID

# A ROS name token: a letter, then letters, digits and single underscores (design.ros2.org, "Topic and
# Service name mapping": no leading digit, no "__", no "/" inside a token).
_TOKEN = re.compile(r"[A-Za-z](?:[A-Za-z0-9]|_(?!_))*")
_TYPE = re.compile(r"([A-Za-z][A-Za-z0-9_]*)/(msg|srv)/([A-Z][A-Za-z0-9]*)")
_HEX = re.compile(r"[0-9a-f]{1,32}")


class EntityKind(enum.StrEnum):
    """`<entity_kind>` of a liveliness token."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


class Reliability(enum.IntEnum):    # rmw_qos_reliability_policy_e
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class Durability(enum.IntEnum):     # rmw_qos_durability_policy_e
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class History(enum.IntEnum):        # rmw_qos_history_policy_e
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclass(frozen=True)
class Qos:
    """The QoS a token announces. Deadline, lifespan and liveliness are rmw_zenoh's defaults (it implements
    none of them), so their fields are always empty."""

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10

    DEFAULT = (Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 42)   # rmw_zenoh's qos.cpp

    def keyexpr(self) -> str:
        """`qos_to_keyexpr`: each value equal to rmw_zenoh's default is left empty."""
        values = (self.reliability, self.durability, self.history, self.depth)
        r, d, h, n = (("" if v == default else str(int(v))) for v, default in zip(values, self.DEFAULT))
        return f"{r}:{d}:{h},{n}:,:,:,,"


def check_domain(domain: object) -> int:
    if isinstance(domain, bool) or not isinstance(domain, int) or not 0 <= domain <= MAX_DOMAIN_ID:
        raise KeyExprError(f"ROS domain id must be an integer 0..{MAX_DOMAIN_ID}")
    return domain


def check_token(name: object, what: str = "ROS name token") -> str:
    """A letter, then letters, digits and single underscores (what a ROS 2 name token may be)."""
    if not isinstance(name, str) or len(name) > 64 or _TOKEN.fullmatch(name) is None:
        raise KeyExprError(f"{what} {name!r}: a letter, then letters, digits and single underscores (ROS 2 names)")
    return name


def fully_qualified(namespace: str, name: str) -> str:
    """``/<namespace>/<name>`` from tokens, e.g. ("robot1", "odom") → ``/robot1/odom``."""
    return f"/{check_token(namespace, 'namespace')}/{check_token(name, 'topic name')}"


def mangle(name: str) -> str:
    """`mangle_name`: every '/' replaced by '%'."""
    return name.replace("/", SLASH_REPLACEMENT)


def dds_type_name(ros_type: str) -> str:
    """``pkg/msg/Name`` → ``pkg::msg::dds_::Name_`` (the type name as rmw_zenoh puts it in keys)."""
    match = _TYPE.fullmatch(ros_type) if isinstance(ros_type, str) else None
    if match is None:
        raise KeyExprError(f"{ros_type!r} is not a ROS 2 interface type name (pkg/msg/Name)")
    package, kind, name = match.groups()
    return f"{package}::{kind}::dds_::{name}_"


def type_hash(ros_type: str) -> str:
    try:
        return TYPE_HASHES[ros_type]
    except KeyError:
        raise KeyExprError(f"no pinned {DISTRO} type hash for {ros_type!r}") from None


def topic_key(domain: int, fq_name: str, ros_type: str) -> str:
    """``<domain>/<fully qualified name without leading '/'>/<DDS type name>/<RIHS01 hash>``."""
    return f"{check_domain(domain)}/{_check_fq(fq_name)[1:]}/{dds_type_name(ros_type)}/{type_hash(ros_type)}"


def _check_fq(fq_name: str) -> str:
    if not isinstance(fq_name, str) or not fq_name.startswith("/") or len(fq_name) > 256:
        raise KeyExprError(f"{fq_name!r}: a fully qualified ROS name starts with '/'")
    for token in fq_name[1:].split("/"):
        check_token(token)
    return fq_name


def _check_zid(session_id: str) -> str:
    if not isinstance(session_id, str) or _HEX.fullmatch(session_id) is None:
        raise KeyExprError(f"{session_id!r} is not a Zenoh session id (1..32 lower-case hex digits)")
    return session_id


def _mangled_ns(namespace: str) -> str:
    return mangle(namespace if namespace == "/" else _check_fq(namespace))


def node_token(domain: int, session_id: str, node_id: int, namespace: str, node: str, enclave: str = "/") -> str:
    """The node's liveliness token (kind NN: its entity id is its node id)."""
    return "/".join((ADMIN_SPACE, str(check_domain(domain)), _check_zid(session_id), str(int(node_id)),
                     str(int(node_id)), EntityKind.NODE.value, _mangled_ns(enclave), _mangled_ns(namespace),
                     check_token(node, "node name")))


def entity_token(domain: int, session_id: str, node_id: int, entity_id: int, kind: EntityKind, namespace: str,
                 node: str, fq_name: str, ros_type: str, qos: Qos = Qos(), enclave: str = "/") -> str:
    """A publisher's, subscription's, service's or client's liveliness token."""
    kind = EntityKind(kind)
    if kind is EntityKind.NODE:
        raise KeyExprError("a node's token is node_token's")
    base = node_token(domain, session_id, node_id, namespace, node, enclave).split("/")
    base[4], base[5] = str(int(entity_id)), kind.value
    return "/".join((*base, mangle(_check_fq(fq_name)), dds_type_name(ros_type), type_hash(ros_type), qos.keyexpr()))


def gid_of(token: str) -> bytes:
    """An entity's 16-byte GID: XXH3-128 of its liveliness token, low 64 bits then high 64 bits, little-endian."""
    import xxhash      # the 'ros2' extra: only a ROS 2 node needs it

    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(GID_SIZE, "little")


@dataclass(frozen=True, slots=True)
class Attachment:
    """The attachment of every rmw_zenoh publication: sequence number, source timestamp, publisher GID."""

    sequence_number: int
    source_timestamp_ns: int       # ns since the UNIX epoch
    gid: bytes

    def __post_init__(self) -> None:
        for value, what in ((self.sequence_number, "sequence number"), (self.source_timestamp_ns, "timestamp")):
            if isinstance(value, bool) or not isinstance(value, int) or not _INT64[0] <= value <= _INT64[1]:
                raise BadAttachment(f"the attachment's {what} must be an int64")
        if not isinstance(self.gid, bytes) or len(self.gid) != GID_SIZE:
            raise BadAttachment(f"the attachment's GID must be {GID_SIZE} bytes")

    def encode(self) -> bytes:
        return _ATTACHMENT.pack(self.sequence_number, self.source_timestamp_ns, GID_SIZE, self.gid)

    @classmethod
    def decode(cls, data: object) -> Attachment:
        """Exactly 33 bytes with a GID length of 16, else `BadAttachment`."""
        if not isinstance(data, (bytes, bytearray, memoryview)) or len(data) != ATTACHMENT_SIZE:
            raise BadAttachment(f"an rmw_zenoh attachment is {ATTACHMENT_SIZE} bytes")
        seq, stamp, gid_len, gid = _ATTACHMENT.unpack(bytes(data))
        if gid_len != GID_SIZE:
            raise BadAttachment(f"the attachment's GID length is {gid_len}, not {GID_SIZE}")
        return cls(seq, stamp, gid)
