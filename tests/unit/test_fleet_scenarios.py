"""tools/fleet_scenarios.py's pure parts: the shipped scenarios are usable, bad ones are refused by name."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from fleet_scenarios import SCENARIOS, ScenarioError, check_poses, scenario


@pytest.mark.parametrize("site, name", [(s, n) for s in SCENARIOS for n in SCENARIOS[s]])
def test_every_shipped_start_and_goal_is_clear_on_its_map(site: str, name: str) -> None:
    legs = scenario(site, name)
    check_poses(site, legs)
    assert 2 <= len(legs) <= 3
    starts = [s for s, _ in legs]
    assert all(((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2) ** 0.5 >= 0.45
               for i, a in enumerate(starts) for b in starts[i + 1:])    # the fleet file's minimum spacing


def test_a_pose_in_a_wall_or_off_the_map_is_refused_naming_it() -> None:
    legs = [((1.4, -1.5, 0.0), (-3.45, 0.0, 0.0)), ((4.3, -1.5, 0.0), (500.0, 0.0, 0.0))]
    with pytest.raises(ScenarioError, match=r"chefbot1 goal \(-3.45, 0.0\), chefbot2 goal \(500.0, 0.0\)"):
        check_poses("hotel", legs)


def test_an_unknown_scenario_names_the_ones_there_are() -> None:
    with pytest.raises(ScenarioError, match="hotel/head_on"):
        scenario("hotel", "tango")
