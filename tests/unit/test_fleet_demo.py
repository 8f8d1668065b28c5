"""tools/fleet_demo.py's pure parts: the seeded order stream, the figures, settings."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from fleet_demo import FleetDemoError, order_stream, settings, summarise

ENV = ("CHEFBOT_DEMO_WORLD", "CHEFBOT_DEMO_MAP", "CHEFBOT_DEMO_TABLES_FILE", "CHEFBOT_DEMO_FLEET_FILE",
       "CHEFBOT_DEMO_TABLES", "CHEFBOT_DEMO_DRIVE", "CHEFBOT_DEMO_ORDERS", "CHEFBOT_DEMO_ORDER_EVERY",
       "CHEFBOT_DEMO_SEED", "CHEFBOT_DEMO_POLICY")


def test_the_order_stream_is_seeded_one_or_two_distinct_tables_poisson_gaps() -> None:
    tables = [f"t{i}" for i in range(9)]
    a = order_stream(tables, 200, 20.0, seed=3)
    assert a == order_stream(tables, 200, 20.0, seed=3) and a != order_stream(tables, 200, 20.0, seed=4)
    assert a[0][0] == 0.0 and all(t1 >= t0 for (t0, _), (t1, _) in zip(a, a[1:], strict=False))
    assert {len(t) for _, t in a} == {1, 2} and all(len(set(t)) == len(t) for _, t in a)
    gaps = [t1 - t0 for (t0, _), (t1, _) in zip(a, a[1:], strict=False)]
    assert 16.0 < sum(gaps) / len(gaps) < 24.0         # mean 20 s within the spread of 199 gaps
    assert order_stream(["only"], 3, 5.0, 0)[1][1] == ["only"]
    with pytest.raises(FleetDemoError):
        order_stream(tables, 0, 20.0, 0)


def test_the_figures_count_only_delivered_orders() -> None:
    orders = [{"placed": 0.0, "ended": 100.0, "ok": True}, {"placed": 10.0, "ended": 50.0, "ok": True},
              {"placed": 20.0, "ended": 400.0, "ok": False}]
    f = summarise(orders, 2)
    assert f["delivered"] == 2 and f["orders"] == 3
    assert f["makespan_s"] == pytest.approx(400.0)
    assert f["orders_per_hour"] == pytest.approx(2 / 400.0 * 3600.0)
    assert f["wait_median_s"] == pytest.approx(70.0) and f["wait_p95_s"] == pytest.approx(100.0)
    assert f["wait_mean_s"] == pytest.approx(70.0)


@pytest.mark.parametrize("env, match", [
    ({"CHEFBOT_DEMO_ROBOTS": "two"}, "whole number"),
    ({"CHEFBOT_DEMO_ROBOTS": "0"}, "needs 1 or more"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_POLICY": "fastest"}, "insertion or nearest_idle"),
    ({"CHEFBOT_DEMO_ROBOTS": "4"}, "robots:=4 asked, but the file lists 3"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_WORLD": "chefbot_sim/worlds/cafe.yaml"}, "needs FLEET_FILE"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_DRIVE": "magic"}, "plugin or firmware"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_FLEET_FILE": "/nonexistent.yaml"}, "does not exist"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_TABLES": "table_1,bar_9"}, "unknown tables .'bar_9'."),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_ORDERS": "many"}, "ORDERS must be a number"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_ORDER_EVERY": "-1"}, "gap > 0"),
])
def test_bad_settings_are_named(monkeypatch: pytest.MonkeyPatch, env: dict, match: str) -> None:
    for k in ENV:
        monkeypatch.delenv(k, raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    with pytest.raises(FleetDemoError, match=match):
        settings()


def test_a_fleet_file_without_a_kitchen_is_refused(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    for k in ENV:
        monkeypatch.delenv(k, raising=False)
    fleet = tmp_path / "fleet.yaml"
    fleet.write_text("robots:\n  - {name: a, parking: {x: 0, y: 0}}\n  - {name: b, parking: {x: 0, y: 1}}\n")
    monkeypatch.setenv("CHEFBOT_DEMO_ROBOTS", "2")
    monkeypatch.setenv("CHEFBOT_DEMO_FLEET_FILE", str(fleet))
    with pytest.raises(FleetDemoError, match="no kitchen pose"):
        settings()


def test_the_hotel_default_is_one_order_per_table_on_average(monkeypatch: pytest.MonkeyPatch) -> None:
    for k in ENV:
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("CHEFBOT_DEMO_ROBOTS", "3")
    cfg = settings()
    assert [r.name for r in cfg["robots"]] == ["chefbot1", "chefbot2", "chefbot3"]
    assert len(cfg["stream"]) == 9 and cfg["drive"] == "plugin"
    assert {t for _, ts in cfg["stream"] for t in ts} <= {f"table_{i}" for i in range(1, 10)}


def test_paths_outside_the_workspace_are_shown_whole(tmp_path: Path) -> None:
    # bench_fleet_stream runs the demo with CHEFBOT_DEMO_DIR in /tmp: its progress lines must not crash
    from fleet_demo import ROOT, shown
    assert shown(ROOT / "build" / "demo" / "fleet.json") == "build/demo/fleet.json"
    assert shown(tmp_path / "roslaunch.log") == str(tmp_path / "roslaunch.log")
