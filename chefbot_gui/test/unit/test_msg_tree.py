"""Messages → (field, type, value) trees for the Topic Monitor, with real generated messages (no master)."""
from __future__ import annotations

import genpy
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import Image, LaserScan
from std_msgs.msg import String

from chefbot_gui.msg_tree import TreeNode, fmt_scalar, message_tree


def test_nested_fields_with_types_and_values() -> None:
    msg = PoseStamped()
    msg.header.stamp = genpy.Time(12, 5_000_000)
    msg.header.frame_id = "map"
    msg.pose.position.x = 1.25
    msg.pose.orientation.w = 1.0
    t = message_tree(msg)
    assert t.type == "geometry_msgs/PoseStamped"
    assert [c.name for c in t.children] == ["header", "pose"]
    assert t.find("header.stamp").value == "12.005000000"
    assert t.find("header.frame_id").value == "'map'"
    x = t.find("pose.position.x")
    assert (x.type, x.value) == ("float64", "1.25")
    assert t.find("pose.orientation").type == "geometry_msgs/Quaternion"
    assert t.find("pose.nope") is None


def test_long_arrays_are_shortened() -> None:
    scan = LaserScan(ranges=[float(i) for i in range(100)], intensities=[])
    t = message_tree(scan, max_items=4)
    r = t.find("ranges")
    assert r.value == "100 items" and r.type == "float32[]"
    assert [c.name for c in r.children] == ["[0]", "[1]", "[2]", "[3]", "…"]
    assert r.children[-1].value == "96 more, 100 in all"
    assert t.find("ranges[2]").value == "2"
    assert t.find("intensities").value == "0 items"


def test_byte_arrays_show_a_hex_preview() -> None:
    img = Image(width=2, height=1, encoding="rgb8", step=6, data=bytes(range(40)))
    t = message_tree(img, max_bytes=4)
    assert t.find("data").value == "40 bytes: 00 01 02 03 …"


def test_strings_nan_bool_and_negative_durations() -> None:
    assert message_tree(String(data="x" * 300), max_chars=5).find("data").value == "'xxxxx'…"
    assert fmt_scalar(float("nan")) == "nan"
    assert fmt_scalar(True) == "true"
    assert fmt_scalar(genpy.Duration(-1, 500_000_000)) == "-0.500000000"


def test_depth_limit_and_non_messages() -> None:
    scan = LaserScan()
    assert message_tree(scan, max_depth=1).find("header").value == "(too deep to show)"
    assert message_tree(42, "x", "int32") == TreeNode("x", "int32", "42")
    assert message_tree(7, "x", "int32[]").value == "<int, expected an array>"
