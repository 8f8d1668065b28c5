"""Footprint from the URDF: no collision body sticks out; radii; bad inputs."""
from __future__ import annotations

import numpy as np
import pytest

from chefbot_navigation.footprint import circle_footprint, footprint_from_urdf, polygon_footprint


@pytest.fixture(scope="module")
def urdf() -> str:
    model = pytest.importorskip("chefbot_description.model")
    return model.expand_xacro()


def test_no_collision_body_of_the_urdf_sticks_out(urdf: str) -> None:
    from chefbot_description.model import parse_urdf
    from chefbot_navigation.footprint import collision_outlines

    fp = footprint_from_urdf(urdf)
    outlines = collision_outlines(parse_urdf(urdf))
    names = {n for n, _ in outlines}
    assert {"base_link", "camera_link", "wheel_left_link", "wheel_right_link"} <= names
    for name, pts in outlines:
        assert fp.contains(pts, tol=1e-6).all(), f"{name} sticks out of the footprint"


def test_camera_box_sets_the_circumscribed_radius(urdf: str) -> None:
    fp = footprint_from_urdf(urdf)
    # camera_link box: x 0.13 +- 0.0315, y +- 0.1395 -> corner at 0.2134 m; base plates r 0.15
    assert fp.circumscribed_radius == pytest.approx(np.hypot(0.13 + 0.0315, 0.1395), abs=2e-3)
    assert fp.inscribed_radius == pytest.approx(0.15, abs=2e-3)
    padded = footprint_from_urdf(urdf, padding=0.01)
    assert padded.inscribed_radius == pytest.approx(0.16, abs=2e-3)
    assert padded.circumscribed_radius == pytest.approx(fp.circumscribed_radius + 0.01, abs=2e-3)


def test_samples_cover_the_polygon() -> None:
    fp = polygon_footprint([[0.3, 0.2], [-0.2, 0.2], [-0.2, -0.2], [0.3, -0.2]])
    s = fp.samples(0.02)
    assert fp.contains(s, tol=1e-9).all()
    assert s[:, 0].max() == pytest.approx(0.3) and s[:, 1].min() == pytest.approx(-0.2)
    assert fp.inscribed_radius == pytest.approx(0.2) and fp.circumscribed_radius == pytest.approx(np.hypot(0.3, 0.2))
    assert circle_footprint(0.2).inscribed_radius == pytest.approx(0.2)


@pytest.mark.parametrize("pts, match", [([[0, 0], [1, 1]], ">= 3"), ([[1, 0], [2, 0], [3, 0]], "no area"),
                                        ([[1, 1], [2, 1], [2, 2]], "origin"),
                                        ([[0, 0], [1, float("nan")], [0, 1]], "finite")])
def test_bad_polygons_are_refused(pts, match) -> None:
    with pytest.raises(ValueError, match=match):
        polygon_footprint(pts)


def test_urdf_without_collisions_is_refused() -> None:
    pytest.importorskip("chefbot_description.model")
    xml = '<robot name="r"><link name="base_footprint"/></robot>'
    with pytest.raises(ValueError, match="no <collision>"):
        footprint_from_urdf(xml)


def test_prefixed_urdf_gives_the_same_footprint_in_the_prefixed_base(urdf: str) -> None:
    # a robot in namespace chefbot1: links chefbot1/...; move_base reads it in its robot_base_frame
    from chefbot_description.model import expand_xacro
    from chefbot_navigation.footprint import resolve_footprint

    prefixed = expand_xacro(args={"frame_prefix": "chefbot1/"})
    fp, _ = resolve_footprint("urdf", 0.01, 0.2, prefixed, "chefbot1/base_footprint")
    ref = footprint_from_urdf(urdf, padding=0.01)
    assert fp.inscribed_radius == pytest.approx(ref.inscribed_radius)
    assert fp.circumscribed_radius == pytest.approx(ref.circumscribed_radius)
    with pytest.raises(ValueError):
        resolve_footprint("urdf", 0.01, 0.2, prefixed, "base_footprint")   # names a frame the URDF lacks
