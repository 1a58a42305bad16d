"""The Foxglove screenshot of the MCAP page: the picture is there, and its layout names topics bendsense writes."""

import re
import struct
from pathlib import Path

from bendsense.interop.ros2 import TOPICS

ROOT = Path(__file__).resolve().parents[2]


def test_screenshot_is_a_png_referenced_by_the_mcap_docs():
    png = (ROOT / "docs" / "img" / "foxglove.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", png[16:24])
    assert (width, height) == (1600, 1000)
    assert "](img/foxglove.png)" in (ROOT / "docs" / "formats.md").read_text(encoding="utf-8")


def test_layout_of_the_screenshot_uses_the_topics_and_fields_of_the_mcap():
    layout = (ROOT / "tools" / "foxglove" / "layout.js").read_text(encoding="utf-8")
    paths = re.findall(r'value: "(/bendsense/[^"]+)"', layout)
    assert paths
    topics = {p.split(".")[0] for p in paths}
    assert topics <= set(TOPICS.values()) and {"/bendsense/wrench", "/bendsense/pressure", "/bendsense/shape"} <= topics
    # the fields of the standard ROS 2 messages bendsense writes (WrenchStamped, FluidPressure, Path)
    fields = {p.split(".", 1)[1] for p in paths}
    assert fields == {"wrench.force.x", "wrench.force.y", "fluid_pressure", "poses[:].pose.position.y",
                      "poses[:].pose.position.x"}
