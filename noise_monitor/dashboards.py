"""Dashboard layouts for the monitor's topics: Foxglove (layout JSON) and PlotJuggler (layout XML).

Both show the per-source sigma (PN, DCSN, RN, total, model) and the measured noise (in the image; from frame
differences where the camera holds still) in DN, xi and its filtered value with the
alarm threshold band (+-``xi_threshold``, the threshold in force, published per frame), the alarm state
and, in Foxglove, ``~/debug_image`` and the camera's /diagnostics level. They read the node's topics (live,
through foxglove_bridge, ``--foxglove PORT`` or PlotJuggler's ROS 2 subscriber) and the replay's MCAP,
which carry the same names. ``config/foxglove_layout.json`` and ``config/plotjuggler_layout.xml`` are
written by :func:`write_layouts` (``python -m noise_monitor.dashboards config``); a test keeps them in step.
The Foxglove layout is built with the ``foxglove.layouts`` classes of foxglove-sdk (the ``live`` extra).
"""
from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Literal

from msg_adapters.diagnostics import jazzy_typestore
from msg_adapters.outputs import DEFAULT_NAMESPACE, DIAGNOSTICS_TOPIC, NUMBER_TYPE, debug_image_topic, namespace_prefix

FOXGLOVE_FILE = "foxglove_layout.json"
PLOTJUGGLER_FILE = "plotjuggler_layout.xml"
#: Per-source sigma series (key, label, colour); all in DN.
SIGMA_SERIES = (("sigma_pn", "PN (photon shot)", "#1f77b4"), ("sigma_dcsn", "DCSN (dark current shot)", "#ff7f0e"),
                ("sigma_rn", "RN (readout)", "#2ca02c"), ("sigma_total", "total (estimator)", "#7f7f7f"),
                ("sigma_model", "model (metadata)", "#9467bd"), ("sigma_image", "measured in the image", "#e377c2"),
                ("sigma_temporal", "measured from frame differences (still view)", "#17becf"))
XI_SERIES = (("xi", "xi", "#d62728"), ("xi_filtered", "xi filtered (alarm input)", "#8c564b"))
BAND_COLOUR = "#bcbd22"
#: Foxglove user-script output: the band's edges from the published threshold.
BAND_TOPIC = "/foxglove_script/xi_threshold_band"
#: PlotJuggler custom series: -xi_threshold (the upper edge is the topic itself).
LOWER_EDGE = "-xi_threshold"
#: diagnostic_msgs/DiagnosticStatus levels.
LEVELS = ((0, "OK", "#2ca02c"), (1, "WARN", "#ff7f0e"), (2, "ERROR", "#d62728"), (3, "STALE", "#7f7f7f"))


def number_field(type_name: str = NUMBER_TYPE) -> list[str]:
    """Field path of the number in a per-frame topic: the first floating-point leaf of its ROS 2 type
    (std_msgs/Float32: ``data``; geometry_msgs/Vector3Stamped: ``vector.x``)."""
    ts = jazzy_typestore()
    for name, (_, detail) in ts.fielddefs[type_name][1]:
        if isinstance(detail, str):
            try:
                return [name, *number_field(detail)]
            except LookupError:
                continue
        elif detail[0] in ("float32", "float64"):
            return [name]
    raise LookupError(f"{type_name} has no floating-point field")


def stamped(type_name: str = NUMBER_TYPE) -> bool:
    """True when the per-frame numbers carry a header (plots then use the image's stamp)."""
    return any(name == "header" for name, _ in jazzy_typestore().fielddefs[type_name][1])


def status_name(camera_name: str) -> str:
    """The monitor's DiagnosticStatus name (``noise_monitor: <camera_name>``)."""
    return f"noise_monitor: {camera_name}"


def foxglove_layout(namespace: str = DEFAULT_NAMESPACE, camera_name: str = "camera",
                    number_type: str = NUMBER_TYPE) -> dict:
    """The Foxglove layout as a JSON object (``foxglove.layouts.Layout``); ``number_type``: the per-frame
    topics' message type."""
    import foxglove.layouts as fl

    ns = namespace_prefix(namespace)
    field = "." + ".".join(number_field(number_type))
    # stamped numbers plot at the image's header stamp; Float32 ones at the log time (= the image stamp in the
    # replay's MCAP and over --foxglove; the receive time through foxglove_bridge), like the band script's output
    when: Literal["headerStamp", "receiveTime"] = "headerStamp" if stamped(number_type) else "receiveTime"
    sigma = fl.PlotPanel(title="Noise per source [DN]", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=f"{ns}/{k}{field}", label=label, color=c, timestamp_method=when)
               for k, label, c in SIGMA_SERIES],
        y_axis_label="sigma [DN]", x_axis_label="time [s]", show_legend=True, legend_display="top", is_synced=True))
    band = [fl.PlotSeries(value=f"{BAND_TOPIC}.{edge}", label=f"{sign}xi_threshold", color=BAND_COLOUR,
                          line_style="dashed", timestamp_method="receiveTime") for edge, sign in (("upper", "+"), ("lower", "-"))]
    xi = fl.PlotPanel(title="xi = model - measured noise [DN] and the alarm threshold", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=f"{ns}/{k}{field}", label=label, color=c, timestamp_method=when)
               for k, label, c in XI_SERIES] + band,
        y_axis_label="xi [DN]", x_axis_label="time [s]", show_legend=True, legend_display="top", is_synced=True))
    level_path = f'{DIAGNOSTICS_TOPIC}.status[:]{{name=="{status_name(camera_name)}"}}.level'
    states = fl.StateTransitionsPanel(title="Alarm and /diagnostics level", config=fl.StateTransitionsConfig(
        is_synced=True, x_axis_label="time [s]", paths=[
            fl.StateTransitionsSeries(value=f"{ns}/alarm{field}", label="xi alarm", timestamp_method=when,
                                      custom_states=fl.StateTransitionsDiscreteCustomStates(states=[
                                          fl.StateTransitionsDiscreteCustomState(value="0", label="ok", color="#2ca02c"),
                                          fl.StateTransitionsDiscreteCustomState(value="1", label="ALARM",
                                                                                 color="#d62728")])),
            fl.StateTransitionsSeries(value=level_path, label="/diagnostics level", timestamp_method="headerStamp",
                                      custom_states=fl.StateTransitionsDiscreteCustomStates(states=[
                                          fl.StateTransitionsDiscreteCustomState(value=str(v), label=n, color=c)
                                          for v, n, c in LEVELS]))]))
    indicator = fl.IndicatorPanel(title="Camera noise status", config=fl.IndicatorConfig(
        path=level_path, style="background", rules=[fl.IndicatorRule(operator="=", raw_value=str(v), label=n, color=c)
                                                    for v, n, c in LEVELS],
        fallback_label="no status", fallback_color="#7f7f7f"))
    image = fl.ImagePanel(title="Debug image: patches green |xi| < threshold, red image noisier, blue model noisier",
                          config=fl.ImageConfig(image_mode=fl.ImageModeConfig(image_topic=debug_image_topic(ns))))
    script = f'''// The +-xi_threshold band around xi: the threshold in force, published with every frame.
import {{ Input }} from "./types.ts";

type Output = {{ upper: number; lower: number }};

export const inputs = ["{ns}/xi_threshold"];
export const output = "{BAND_TOPIC}";

export default function script(event: Input<"{ns}/xi_threshold">): Output {{
  const threshold = event.message{field};
  return {{ upper: threshold, lower: -threshold }};
}}
'''
    layout = fl.Layout(
        content=fl.SplitContainer(direction="row", items=[
            fl.SplitItem(proportion=3, content=fl.SplitContainer(direction="column", items=[
                fl.SplitItem(proportion=2, content=sigma), fl.SplitItem(proportion=2, content=xi),
                fl.SplitItem(proportion=1, content=states)])),
            fl.SplitItem(proportion=2, content=fl.SplitContainer(direction="column", items=[
                fl.SplitItem(proportion=3, content=image), fl.SplitItem(proportion=1, content=indicator)]))]),
        user_scripts={"xi_threshold_band": fl.UserScript(name="xi threshold band", source_code=script)})
    return json.loads(layout.to_json())


def plotjuggler_layout(namespace: str = DEFAULT_NAMESPACE, number_type: str = NUMBER_TYPE) -> str:
    """The PlotJuggler layout XML (curves ``<topic>/<field>``; loads an MCAP or subscribes to ROS 2 topics)."""
    ns = namespace_prefix(namespace)
    field = "/" + "/".join(number_field(number_type))
    root = ET.Element("root")
    tabs = ET.SubElement(root, "tabbed_widget", {"name": "Main Window", "parent": "main_window"})
    tab = ET.SubElement(tabs, "Tab", tab_name="noise monitor", containers="1")
    splitter = ET.SubElement(ET.SubElement(tab, "Container"), "DockSplitter", orientation="-", count="3",
                             sizes="0.4;0.4;0.2")
    band = ((f"{ns}/xi_threshold{field}", BAND_COLOUR), (LOWER_EDGE, BAND_COLOUR))
    plots = (("noise per source [DN]", [(f"{ns}/{k}{field}", c) for k, _, c in SIGMA_SERIES]),
             ("xi [DN] and the alarm threshold band", [(f"{ns}/{k}{field}", c) for k, _, c in XI_SERIES] + list(band)),
             ("xi alarm (1 = active)", [(f"{ns}/alarm{field}", "#d62728")]))
    for title, curves in plots:
        plot = ET.SubElement(ET.SubElement(splitter, "DockArea", name=title), "plot", mode="TimeSeries",
                             style="Lines", flip_x="false", flip_y="false")
        ET.SubElement(plot, "limitY")
        for name, colour in curves:
            ET.SubElement(plot, "curve", name=name, color=colour)
    ET.SubElement(tabs, "currentTabIndex", index="0")
    ET.SubElement(root, "use_relative_time_offset", enabled="1")
    topics = [f"{ns}/{k}" for k, _, _ in SIGMA_SERIES + XI_SERIES] + [f"{ns}/alarm", f"{ns}/xi_threshold",
                                                                      DIAGNOSTICS_TOPIC]
    plugins = ET.SubElement(root, "Plugins")
    ET.SubElement(plugins, "plugin", ID="DataLoad MCAP")
    ros2 = ET.SubElement(plugins, "plugin", ID="ROS2 Topic Subscriber")
    ET.SubElement(ros2, "use_header_stamp", value="true" if stamped(number_type) else "false")
    selected = ET.SubElement(ros2, "selected_topics")
    for topic in topics:
        ET.SubElement(selected, "topic", name=topic)
    maths = ET.SubElement(root, "customMathEquations")
    snippet = ET.SubElement(maths, "snippet", name=LOWER_EDGE, language="LUA")
    ET.SubElement(snippet, "global").text = ""
    ET.SubElement(snippet, "function").text = "return -value"
    ET.SubElement(snippet, "linked_source").text = f"{ns}/xi_threshold{field}"
    ET.indent(root, " ")
    return "<?xml version='1.0' encoding='UTF-8'?>\n" + ET.tostring(root, "unicode") + "\n"


def write_layouts(folder: str | Path) -> list[Path]:
    """Write both layouts for the default namespace and camera into ``folder``."""
    out = Path(folder)
    fox, pj = out / FOXGLOVE_FILE, out / PLOTJUGGLER_FILE
    fox.write_text(json.dumps(foxglove_layout(), indent=2) + "\n")
    pj.write_text(plotjuggler_layout())
    return [fox, pj]


if __name__ == "__main__":
    for path in write_layouts(sys.argv[1] if len(sys.argv) > 1 else "config"):
        print(path)
