"""The Foxglove layout of sharedctl's channels (live view and recordings alike): deploy/foxglove/sharedctl-layout.json.

Made with foxglove-sdk's layout model (``foxglove.layouts``), so the file is what the SDK's
Foxglove version imports (Layout → Import from file). Left, the 3D panel on the SceneUpdate
(top-down, world frame); right, plots of the margin and of the sharing gains, the authority as
state transitions, the Log panel on the events, and raw RobotState messages.

``sharedctl foxglove --write-layout FILE [--robot-id ID]`` writes it; the file in deploy/ is
checked against this (tests/services/test_foxglove_views.py).
"""
from __future__ import annotations

import json

import foxglove.layouts as fl

from sharedctl.protocol import keys

from ..recording.scene import FRAME
from ..recording.views import log_topic, scene_topic


def layout(robot: str = "robot1") -> fl.Layout:
    state, truth, events = keys.state_key(robot), keys.truth_key(robot), keys.events_key(robot)
    scene = fl.ThreeDeePanel(title="admissible set, robot, reference, wish", config=fl.ThreeDeeConfig(
        follow_tf=FRAME, fixed_frame=FRAME, follow_mode="follow-none",
        camera_state=fl.ThreeDeeCameraState(perspective=False, distance=12.0, phi=0.0, theta_offset=0.0,
                                            target=(0.0, 2.0, 0.0)),
        topics={scene_topic(robot): fl.BaseRendererSceneUpdateTopicSettings(visible=True)}))
    margin = fl.PlotPanel(title="margins (m)", config=fl.PlotConfig(paths=[
        fl.PlotSeries(value=f"{state}.min_margin", label="min margin (estimate)"),
        fl.PlotSeries(value=f"{state}.region_margins[0]", label="region 1 margin")], show_legend=True))
    gains = fl.PlotPanel(title="sharing", config=fl.PlotConfig(paths=[
        fl.PlotSeries(value=f"{state}.k_s", label="k_s"), fl.PlotSeries(value=f"{state}.k_h", label="k_h"),
        fl.PlotSeries(value=f"{state}.k_f", label="k_f")], show_legend=True))
    pose = fl.PlotPanel(title="pose: estimate and ground truth (m)", config=fl.PlotConfig(paths=[
        fl.PlotSeries(value=f"{state}.q[0]", label="x"), fl.PlotSeries(value=f"{state}.q[1]", label="y"),
        fl.PlotSeries(value=f"{truth}.q[0]", label="x true"), fl.PlotSeries(value=f"{truth}.q[1]", label="y true")],
        show_legend=True))
    authority = fl.StateTransitionsPanel(title="authority", config=fl.StateTransitionsConfig(paths=[
        fl.StateTransitionsSeries(value=f"{state}.authority", label="authority"),
        fl.StateTransitionsSeries(value=f"{state}.estop_active", label="estop")]))
    log = fl.LogPanel(title="events", config=fl.LogConfig(topic_to_render=log_topic(robot), show_name=True))
    raw = fl.RawMessagesPanel(title="RobotState", config=fl.RawMessagesConfig(topic_path=state))
    raw_events = fl.RawMessagesPanel(title="events (raw)", config=fl.RawMessagesConfig(topic_path=events))
    right = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(content=margin), fl.SplitItem(content=gains), fl.SplitItem(content=pose),
        fl.SplitItem(content=authority, proportion=0.6),
        fl.SplitItem(content=fl.TabContainer(tabs=[fl.TabItem(title="log", content=log),
                                                   fl.TabItem(title="RobotState", content=raw),
                                                   fl.TabItem(title="events", content=raw_events)]))])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(content=scene, proportion=1.4), fl.SplitItem(content=right)]))


def layout_json(robot: str = "robot1") -> str:
    """The layout as the file holds it (indented, one trailing newline)."""
    return json.dumps(json.loads(layout(robot).to_json()), indent=2) + "\n"
