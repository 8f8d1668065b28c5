"""chefbot_fleet.blocks: two robots standing still in each other's way, and which one gives way."""
from __future__ import annotations

import numpy as np
import pytest

from chefbot_fleet.blocks import Block, BlockConfig, BlockDetector, RobotView, in_the_way


def line(x0: float, x1: float, y: float = 0.0) -> np.ndarray:
    return np.column_stack((np.linspace(x0, x1, 50), np.full(50, y)))


def head_on(**kw) -> list[RobotView]:
    a = RobotView("chefbot1", 0.0, 0.0, 0.2, line(0.0, 3.0), **kw)
    b = RobotView("chefbot2", 0.6, 0.0, 0.2, line(0.6, -3.0))
    return [a, b]


def run(det: BlockDetector, robots: list[RobotView], t0: float, t1: float) -> list[Block]:
    out = []
    for t in np.arange(t0, t1, 0.1):
        out += det.update(float(t), robots)
    return out


def test_head_on_standstill_is_caught_after_stall_time_and_the_later_robot_gives_way() -> None:
    det = BlockDetector(BlockConfig(stall_time=5.0))
    assert run(det, head_on(), 0.0, 4.9) == []
    blocks = run(det, head_on(), 4.9, 5.3)
    assert [(b.yielder, b.other) for b in blocks] == [("chefbot2", "chefbot1")]
    assert blocks[0].stalled_for == pytest.approx(5.0, abs=0.11)
    assert "chefbot2 gives way" in blocks[0].text()
    assert run(det, head_on(), 5.3, 20.0) == []                   # cooldown 15 s
    assert len(run(det, head_on(), 20.0, 21.0)) == 1              # still blocked afterwards: again


def test_the_order_given_decides_who_yields() -> None:
    det = BlockDetector(BlockConfig())
    blocks = run(det, head_on()[::-1], 0.0, 6.0)
    assert [b.yielder for b in blocks] == ["chefbot1"]


@pytest.mark.parametrize("case", ["moving", "passing lanes", "held", "no goal", "one way only"])
def test_no_block(case: str) -> None:
    det = BlockDetector(BlockConfig())
    out = []
    for t in np.arange(0.0, 8.0, 0.1):
        a, b = head_on(held=(case == "held"))
        if case == "moving":
            b.x -= 0.05 * t                                        # 5 cm/s
        if case == "passing lanes":
            b.y, b.path = 0.7, line(0.6, -3.0, 0.7)
        if case == "no goal":
            b.path = np.zeros((0, 2))
        if case == "one way only":
            b.path = line(0.6, 3.0)                                # b drives away from a: a waits, b is slow
        out += det.update(float(t), [a, b])
    assert out == []


def test_in_the_way_looks_only_look_ahead_metres_along_the_plan() -> None:
    a = RobotView("a", 0.0, 0.0, 0.2, np.array([[0.0, 0.0], [3.0, 0.0]]))       # two points: sampled between
    assert in_the_way(a, RobotView("b", 1.4, 0.3, 0.2), 1.5, 0.1)
    assert not in_the_way(a, RobotView("b", 2.0, 0.0, 0.2), 1.5, 0.1)
    assert not in_the_way(a, RobotView("b", 1.0, 0.6, 0.2), 1.5, 0.1)
    behind = RobotView("a", 2.0, 0.0, 0.2, line(0.0, 3.0))                       # plan from the nearest point on
    assert not in_the_way(behind, RobotView("b", 0.5, 0.0, 0.2), 0.8, 0.1)


def test_time_jumping_back_and_forgotten_robots_start_afresh() -> None:
    det = BlockDetector(BlockConfig())
    run(det, head_on(), 10.0, 14.0)
    assert det.stalled_for("chefbot1", 13.9) == pytest.approx(3.9, abs=0.11)
    det.update(1.0, head_on())
    assert det.stalled_for("chefbot1", 1.0) == 0.0
    det.forget("chefbot1")
    assert det.stalled_for("chefbot1", 1.0) == 0.0


@pytest.mark.parametrize("bad", [dict(stall_time=0.0), dict(stall_distance=-1.0), dict(look_ahead=0.0),
                                 dict(clearance=-0.1), dict(cooldown=0.0)])
def test_bad_config_is_refused(bad: dict) -> None:
    with pytest.raises(ValueError):
        BlockConfig(**bad)
