"""Foxglove's well-known message types ``foxglove.Log`` and ``foxglove.SceneUpdate`` in their JSON form.

Foxglove recognises a well-known type by its schema name whatever the encoding; in JSON a time
is ``{"sec", "nsec"}``, an enumeration its integer value, a vector ``{"x", "y", "z"}``. The JSON
Schemas below describe the fields this project writes (the types' full definitions:
https://docs.foxglove.dev/docs/sdk/schemas); the builders return plain dicts in that form.
Pure: no I/O, no SDK.
"""
from __future__ import annotations

import math
from typing import Any

LOG_SCHEMA_NAME = "foxglove.Log"
SCENE_UPDATE_SCHEMA_NAME = "foxglove.SceneUpdate"

# foxglove.LogLevel
LOG_UNKNOWN, LOG_DEBUG, LOG_INFO, LOG_WARNING, LOG_ERROR, LOG_FATAL = range(6)
# foxglove.LinePrimitive type
LINE_STRIP, LINE_LOOP, LINE_LIST = range(3)

_NUMBER = {"type": "number"}


def _object(title: str | None, properties: dict[str, Any], description: str = "") -> dict[str, Any]:
    schema: dict[str, Any] = {"type": "object", "properties": properties, "required": list(properties)}
    if title:
        schema = {"title": title, **schema}
    if description:
        schema["description"] = description
    return schema


def _array(item: dict[str, Any]) -> dict[str, Any]:
    return {"type": "array", "items": item}


_TIME = {"type": "object", "title": "time", "properties": {
    "sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}}
_DURATION = {"type": "object", "title": "duration", "properties": {
    "sec": {"type": "integer"}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}}
_VECTOR3 = _object("foxglove.Vector3", {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER})
_POINT3 = _object("foxglove.Point3", {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER})
_QUATERNION = _object("foxglove.Quaternion", {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER, "w": _NUMBER})
_POSE = _object("foxglove.Pose", {"position": _VECTOR3, "orientation": _QUATERNION})
_COLOR = _object("foxglove.Color", {"r": _NUMBER, "g": _NUMBER, "b": _NUMBER, "a": _NUMBER})
_KEY_VALUE = _object("foxglove.KeyValuePair", {"key": {"type": "string"}, "value": {"type": "string"}})

_PRIMITIVES: dict[str, dict[str, Any]] = {
    "arrows": _object("foxglove.ArrowPrimitive", {
        "pose": _POSE, "shaft_length": _NUMBER, "shaft_diameter": _NUMBER, "head_length": _NUMBER,
        "head_diameter": _NUMBER, "color": _COLOR}),
    "cubes": _object("foxglove.CubePrimitive", {"pose": _POSE, "size": _VECTOR3, "color": _COLOR}),
    "spheres": _object("foxglove.SpherePrimitive", {"pose": _POSE, "size": _VECTOR3, "color": _COLOR}),
    "cylinders": _object("foxglove.CylinderPrimitive", {
        "pose": _POSE, "size": _VECTOR3, "bottom_scale": _NUMBER, "top_scale": _NUMBER, "color": _COLOR}),
    "lines": _object("foxglove.LinePrimitive", {
        "type": {"type": "integer", "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
        "pose": _POSE, "thickness": _NUMBER, "scale_invariant": {"type": "boolean"}, "points": _array(_POINT3),
        "color": _COLOR, "colors": _array(_COLOR), "indices": _array({"type": "integer", "minimum": 0})}),
    "triangles": _object("foxglove.TriangleListPrimitive", {
        "pose": _POSE, "points": _array(_POINT3), "color": _COLOR, "colors": _array(_COLOR),
        "indices": _array({"type": "integer", "minimum": 0})}),
    "texts": _object("foxglove.TextPrimitive", {
        "pose": _POSE, "billboard": {"type": "boolean"}, "font_size": _NUMBER,
        "scale_invariant": {"type": "boolean"}, "color": _COLOR, "text": {"type": "string"}}),
    "models": _object("foxglove.ModelPrimitive", {
        "pose": _POSE, "scale": _VECTOR3, "color": _COLOR, "override_color": {"type": "boolean"},
        "url": {"type": "string"}, "media_type": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"}}),
}
PRIMITIVE_KINDS = tuple(_PRIMITIVES)

_SCENE_ENTITY = _object("foxglove.SceneEntity", {
    "timestamp": _TIME, "frame_id": {"type": "string"}, "id": {"type": "string"}, "lifetime": _DURATION,
    "frame_locked": {"type": "boolean"}, "metadata": _array(_KEY_VALUE),
    **{kind: _array(item) for kind, item in _PRIMITIVES.items()}},
    "A visual element in a 3D scene")
_SCENE_ENTITY_DELETION = _object("foxglove.SceneEntityDeletion", {
    "timestamp": _TIME, "type": {"type": "integer", "description": "0 MATCHING_ID, 1 ALL"}, "id": {"type": "string"}})

SCENE_UPDATE_SCHEMA: dict[str, Any] = _object(SCENE_UPDATE_SCHEMA_NAME, {
    "deletions": _array(_SCENE_ENTITY_DELETION), "entities": _array(_SCENE_ENTITY)},
    "An update to the entities displayed in a 3D scene")

LOG_SCHEMA: dict[str, Any] = _object(LOG_SCHEMA_NAME, {
    "timestamp": _TIME,
    "level": {"type": "integer", "minimum": 0, "maximum": 5,
              "description": "0 UNKNOWN, 1 DEBUG, 2 INFO, 3 WARNING, 4 ERROR, 5 FATAL"},
    "message": {"type": "string"}, "name": {"type": "string"}, "file": {"type": "string"},
    "line": {"type": "integer", "minimum": 0}},
    "A log message")


# ----- builders ----------------------------------------------------------------------
def time_of_ns(ns: int) -> dict[str, int]:
    """Unix ns as ``{"sec", "nsec"}``."""
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def color(r: float, g: float, b: float, a: float = 1.0) -> dict[str, float]:
    return {"r": r, "g": g, "b": b, "a": a}


def point(x: float, y: float, z: float = 0.0) -> dict[str, float]:
    return {"x": float(x), "y": float(y), "z": float(z)}


def pose(x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0) -> dict[str, Any]:
    """A position and a rotation by ``yaw`` about +z (quaternion (0, 0, sin ψ/2, cos ψ/2))."""
    return {"position": point(x, y, z),
            "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2.0), "w": math.cos(yaw / 2.0)}}


def entity(entity_id: str, stamp_ns: int, frame_id: str, metadata: dict[str, str] | None = None,
           **primitives: list[dict[str, Any]]) -> dict[str, Any]:
    """A ``foxglove.SceneEntity`` that stays until it is replaced (lifetime 0); every primitive list present."""
    unknown = set(primitives) - set(PRIMITIVE_KINDS)
    if unknown:
        raise ValueError(f"not a primitive kind: {sorted(unknown)}")
    return {"timestamp": time_of_ns(stamp_ns), "frame_id": frame_id, "id": entity_id,
            "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": False,
            "metadata": [{"key": k, "value": v} for k, v in (metadata or {}).items()],
            **{kind: list(primitives.get(kind, ())) for kind in PRIMITIVE_KINDS}}
