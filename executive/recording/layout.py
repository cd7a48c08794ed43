"""The Foxglove layout for mmexec recordings and live runs, built with foxglove-sdk's
``foxglove.layouts`` on the channel names of :mod:`.channels`, and shipped as
``docs/foxglove/mmexec-layout.json`` (a test keeps the file equal to :func:`layout_json`;
regenerate it with ``python -m mmexec.executive.recording.layout > docs/foxglove/mmexec-layout.json``).

Panels: a 3D view following ``base_link`` (the map grid in its own colours, the scan,
the planned path and the pose), the camera image, the tree's node statuses as a table
and as state transitions over time, the event log as log lines (info and above) and the
raw event records.
"""

from __future__ import annotations

import json
import sys

import foxglove.layouts as fl

from mmexec.executive.recording.channels import (
    BASE_FRAME,
    CAMERA,
    EVENTS,
    LOG,
    MAP,
    PATH,
    POSE,
    SCAN,
    TREE,
)

__all__ = ["layout", "layout_json"]


def layout() -> fl.Layout:
    """The layout (see the module doc)."""
    three_d = fl.ThreeDeePanel(title="map", config=fl.ThreeDeeConfig(
        follow_tf=BASE_FRAME,
        topics={
            MAP: fl.BaseRendererGridTopicSettings(visible=True, color_mode="rgba-fields"),
            SCAN: fl.BaseRendererLaserScanTopicSettings(visible=True, point_size=4.0, color_mode="flat",
                                                        flat_color="#e53935"),
            PATH: fl.BaseRendererPosesTopicSettings(visible=True, type="line", line_width=0.04),
            POSE: fl.BaseRendererPoseTopicSettings(visible=True, type="arrow"),
        }))
    camera = fl.ImagePanel(title="camera", config=fl.ImageConfig(image_mode=fl.ImageModeConfig(image_topic=CAMERA)))
    tree = fl.TablePanel(title="tree", config=fl.TableConfig(topic_path=f"{TREE}.nodes"))
    transitions = fl.StateTransitionsPanel(title="node statuses", config=fl.StateTransitionsConfig(paths=[
        fl.StateTransitionsSeries(value=f"{TREE}.nodes[:].status", label="node", array_expansion="byIndex",
                                  dynamic_label_field="path")]))
    events = fl.LogPanel(title="events", config=fl.LogConfig(topic_to_render=LOG, min_log_level=2, show_name=True))
    raw = fl.RawMessagesPanel(title="event records", config=fl.RawMessagesConfig(topic_path=EVENTS))
    left = fl.SplitContainer(direction="column", items=[fl.SplitItem(proportion=2, content=three_d),
                                                        fl.SplitItem(proportion=1, content=camera)])
    right = fl.SplitContainer(direction="column", items=[fl.SplitItem(proportion=2, content=tree),
                                                         fl.SplitItem(proportion=1, content=transitions),
                                                         fl.SplitItem(proportion=1, content=events),
                                                         fl.SplitItem(proportion=1, content=raw)])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[fl.SplitItem(proportion=3, content=left),
                                                                       fl.SplitItem(proportion=2, content=right)]))


def layout_json() -> str:
    """The layout file's text: the SDK's JSON, indented, with a final newline."""
    return json.dumps(json.loads(layout().to_json()), indent=2) + "\n"


if __name__ == "__main__":
    sys.stdout.write(layout_json())
