"""chefbot_fleet.blocks: two robots standing still in each other's way, and which one gives way."""
from __future__ import annotations

import numpy as np
import pytest

from chefbot_common.grid import GridInfo
from chefbot_fleet.blocks import Block, BlockConfig, BlockDetector, RobotView, in_the_way, room_spot


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


@pytest.mark.parametrize("case", ["moving", "passing lanes", "one way only"])
def test_no_block(case: str) -> None:
    det = BlockDetector(BlockConfig())
    out = []
    for t in np.arange(0.0, 8.0, 0.1):
        a, b = head_on()
        if case == "moving":
            b.x -= 0.05 * t                                        # 5 cm/s
        if case == "passing lanes":
            b.y, b.path = 0.7, line(0.6, -3.0, 0.7)
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
                                 dict(clearance=-0.1), dict(cooldown=0.0), dict(room_margin=-0.1),
                                 dict(room_distance=0.0)])
def test_bad_config_is_refused(bad: dict) -> None:
    with pytest.raises(ValueError):
        BlockConfig(**bad)


def idle_ahead() -> list[RobotView]:
    """chefbot1 drives east along y = 0; chefbot2 has no goal and stands 0.6 m ahead of it."""
    return [RobotView("chefbot1", 0.0, 0.0, 0.2, line(0.0, 3.0)), RobotView("chefbot2", 0.6, 0.0, 0.2)]


def test_an_idle_robot_in_a_stalled_robots_way_makes_room_after_stall_time() -> None:
    det = BlockDetector(BlockConfig(stall_time=5.0))
    assert run(det, idle_ahead(), 0.0, 4.9) == []
    blocks = run(det, idle_ahead(), 4.9, 5.3)
    assert [(b.yielder, b.other, b.idle) for b in blocks] == [("chefbot2", "chefbot1", True)]
    assert "chefbot2 stands idle in chefbot1's way" in blocks[0].text() and "makes room" in blocks[0].text()
    assert run(det, idle_ahead(), 5.3, 20.0) == []                 # cooldown 15 s


@pytest.mark.parametrize("case", ["moving", "beside the plan", "held, no zone wait"])
def test_no_idle_block(case: str) -> None:
    det = BlockDetector(BlockConfig())
    out = []
    for t in np.arange(0.0, 8.0, 0.1):
        a, b = idle_ahead()
        if case == "moving":
            a.x = 0.05 * t
        if case == "beside the plan":
            b.y = 0.7
        if case == "held, no zone wait":
            a.held = True
        out += det.update(float(t), [a, b])
    assert out == []


def test_an_idle_robot_holding_the_zone_another_waits_for_makes_room() -> None:
    det = BlockDetector(BlockConfig())
    a = RobotView("chefbot1", 0.0, 0.0, 0.2, line(0.0, 5.0), held=True)     # waits at the zone's holding point
    b = RobotView("chefbot2", 4.0, 0.0, 0.2)                                # idle inside the zone, 4 m on
    assert run(det, [a, b], 0.0, 6.0, ) == []                              # not asked: no zone wait
    blocks = []
    for t in np.arange(6.0, 12.0, 0.1):
        blocks += det.update(float(t), [a, b], zone_waits=[("chefbot1", "chefbot2")])
    assert [(bl.yielder, bl.other, bl.idle) for bl in blocks] == [("chefbot2", "chefbot1", True)]


def test_an_idle_robot_on_a_robots_goal_or_in_the_zone_it_is_held_for_makes_room_after_idle_confirm() -> None:
    """Not after stall_time (the other robot need not stop first), but once it has stayed so idle_confirm s."""
    cfg = BlockConfig(stall_time=5.0, idle_confirm=2.0)
    det = BlockDetector(cfg)
    a = RobotView("chefbot1", 0.0, 0.0, 0.2, line(0.0, 3.0))                # driving, not stalled
    b = RobotView("chefbot2", 3.0, 0.3, 0.2)                                # idle, 0.3 m from a's goal
    blocks = []
    for t in np.arange(0.0, 2.5, 0.1):
        a.x = 0.3 * t
        blocks += [(float(t), bl) for bl in det.update(float(t), [a, b])]
    assert [(bl.yielder, bl.other, bl.idle, bl.where) for _, bl in blocks] == [("chefbot2", "chefbot1", True, "goal")]
    assert blocks[0][0] == pytest.approx(2.0, abs=0.11)
    assert "chefbot2 stands idle on chefbot1's goal" in blocks[0][1].text()
    b.y = 0.6                                                               # beside the goal: not asked
    assert run(BlockDetector(cfg), [a, b], 0.0, 3.0) == []
    det = BlockDetector(cfg)
    a = RobotView("chefbot1", 0.0, 0.0, 0.2, line(0.0, 5.0), held=True)
    b = RobotView("chefbot2", 4.0, 0.0, 0.2)
    blocks = [bl for t in np.arange(0.0, 2.5, 0.1) for bl in det.update(float(t), [a, b], [("chefbot1", "chefbot2")])]
    assert [(bl.yielder, bl.where) for bl in blocks] == [("chefbot2", "zone")]
    assert "chefbot2 stands idle in the zone chefbot1 waits for" in blocks[0].text()
    a.held = False                  # asked for the zone but not yet at its apron: only after stall_time
    det = BlockDetector(cfg)
    assert [bl for t in np.arange(0.0, 4.0, 0.1) for bl in det.update(float(t), [a, b], [("chefbot1", "chefbot2")])
            ] == []


def test_two_robots_given_goals_together_one_on_the_others_start_neither_is_sent_off() -> None:
    """chefbot2's plan shows first and ends where chefbot1 stands; chefbot1's own goal shows 0.5 s later:
    chefbot1 is not sent off (a make-room goal would replace the goal it was given)."""
    det = BlockDetector(BlockConfig(idle_confirm=2.0))
    a = RobotView("chefbot1", 3.0, 0.0, 0.2)
    b = RobotView("chefbot2", 0.0, 0.0, 0.2, line(0.0, 3.0))
    out = []
    for t in np.arange(0.0, 5.0, 0.1):
        if t >= 0.5:
            a.path = line(3.0, 6.0)
            a.x = 3.0 + 0.3 * (t - 0.5)
        out += det.update(float(t), [a, b])
    assert out == []


def test_a_block_not_resolved_now_is_judged_again_after_the_retry_time() -> None:
    det = BlockDetector(BlockConfig(stall_time=5.0, cooldown=15.0, idle_confirm=0.1))
    a = RobotView("chefbot1", 0.0, 0.0, 0.2, line(0.0, 3.0))
    b = RobotView("chefbot2", 3.0, 0.0, 0.2)
    assert det.update(0.0, [a, b]) == []
    (block,) = det.update(0.1, [a, b])
    det.retry(block, 0.1, 1.0)
    assert det.count == 0
    assert det.update(0.6, [a, b]) == []
    assert len(det.update(1.1, [a, b])) == 1 and det.count == 1


RES = 0.05


def room(free_boxes: list[tuple[float, float, float, float]], size=(8.0, 4.0)) -> tuple[np.ndarray, GridInfo]:
    """Clearance (m to the nearest obstacle) of a map all obstacle but the free (x0, y0, x1, y1) boxes."""
    from scipy import ndimage
    w, h = int(round(size[0] / RES)), int(round(size[1] / RES))
    free = np.zeros((h, w), bool)
    for x0, y0, x1, y1 in free_boxes:
        free[int(round(y0 / RES)):int(round(y1 / RES)), int(round(x0 / RES)):int(round(x1 / RES))] = True
    return np.maximum(ndimage.distance_transform_edt(free) - 0.5, 0.0) * RES, GridInfo(RES, w, h)


def test_room_spot_is_the_nearest_reachable_free_spot_clear_of_the_other_robot_and_its_plan() -> None:
    clearance, info = room([(0.0, 0.0, 8.0, 2.0), (0.0, 2.5, 8.0, 4.0)])   # two halls, a wall between them
    cfg = BlockConfig()
    me = RobotView("idle", 4.0, 1.0, 0.2)
    other = RobotView("busy", 1.0, 1.0, 0.2, line(1.0, 7.0, 1.0))           # drives along y = 1 through me
    x, y = room_spot(clearance, info, None, me, [other], cfg)
    need = 0.2 + 0.2 + cfg.clearance + cfg.room_margin
    assert abs(y - 1.0) >= need - RES                                        # off the plan ...
    assert abs(x - 4.0) < RES                                                # ... straight beside it ...
    assert y < 2.0 - 0.2 - cfg.room_margin + RES                             # ... in its own hall, clear of the wall
    keep = np.zeros(clearance.shape, bool)
    keep[:, int(3.0 / RES):int(5.0 / RES)] = True                            # a zone around it: go past it
    x2, _ = room_spot(clearance, info, keep, me, [other], cfg)
    assert x2 < 3.0 or x2 >= 5.0


def test_no_room_spot_in_a_corridor_the_other_robots_plan_fills() -> None:
    # a 0.8 m wide corridor, and beyond its 0.1 m north wall a hall it cannot reach
    clearance, info = room([(0.0, 1.0, 8.0, 1.8), (0.0, 1.9, 8.0, 4.0)])
    other = RobotView("busy", 1.0, 1.4, 0.2, line(1.0, 7.0, 1.4))
    assert room_spot(clearance, info, None, RobotView("idle", 4.0, 1.4, 0.2), [other], BlockConfig()) is None
    assert room_spot(clearance, info, None, RobotView("idle", 40.0, 1.4, 0.2), [other], BlockConfig()) is None


def test_a_robot_waiting_for_a_zone_in_the_way_of_one_coming_out_gives_way() -> None:
    """chefbot1 waits (held) at an aisle's mouth; chefbot2, coming out, has stood still with chefbot1
    in its way: chefbot1 backs off, whatever the order, and not before stall_time."""
    det = BlockDetector(BlockConfig(stall_time=5.0))
    robots = head_on(held=True)
    assert run(det, robots, 0.0, 4.9) == []
    blocks = run(det, robots, 4.9, 5.3)
    assert [(b.yielder, b.other, b.waiting) for b in blocks] == [("chefbot1", "chefbot2", True)]
    assert "chefbot1 waits for a zone in chefbot2's way" in blocks[0].text()
    det = BlockDetector(BlockConfig())
    assert [b.yielder for b in run(det, robots[::-1], 0.0, 6.0)] == ["chefbot1"]


def test_room_spot_is_reached_past_the_other_robots_not_through_them() -> None:
    """A dead-end aisle 0.6 m wide (x 3.8-4.4, y 0-2) off a hall (y 2-4); the idle robot stands in it, a
    robot waiting for the aisle stands at its mouth: no spot can be reached until that one moves off."""
    clearance, info = room([(0.0, 2.0, 8.0, 4.0), (3.8, 0.0, 4.4, 2.0)])
    keep = np.zeros(clearance.shape, bool)
    keep[:int(2.3 / RES), int(3.5 / RES):int(4.7 / RES)] = True               # the aisle and its apron
    me = RobotView("idle", 4.1, 0.5, 0.2)
    down = np.column_stack((np.full(50, 4.1), np.linspace(2.35, 0.5, 50)))    # its plan: into the aisle
    waiting = RobotView("busy", 4.1, 2.35, 0.2, down, held=True)
    cfg = BlockConfig()
    assert room_spot(clearance, info, keep, me, [waiting], cfg) is None
    x, y = room_spot(clearance, info, keep, me, [waiting], cfg, ghosts=frozenset({"busy"}))
    assert not keep[int(y / RES), int(x / RES)]
    assert np.hypot(x - 4.1, y - 2.35) >= 0.2 + 0.2 + cfg.clearance + cfg.room_margin - RES
    waiting.y = 3.5                                                            # out of the mouth: reachable
    waiting.path = np.column_stack((np.full(50, 4.1), np.linspace(3.5, 0.5, 50)))
    assert room_spot(clearance, info, keep, me, [waiting], cfg) is not None
