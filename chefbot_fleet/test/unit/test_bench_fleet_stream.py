"""bench_fleet_stream's rows from its runs' summaries (no simulation)."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

PATH = Path(__file__).resolve().parents[2] / "bench" / "bench_fleet_stream.py"
spec = importlib.util.spec_from_file_location("chefbot_bench_fleet_stream", PATH)
bench = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench)


def summary(per_hour: float, wait: float, **extra) -> dict:
    base = {"orders": 6, "delivered": 6, "orders_per_hour": per_hour, "wait_mean_s": wait, "wait_median_s": wait,
            "wait_p95_s": 2 * wait, "makespan_s": 600.0, "km": 1.2, "sim_per_wall": 0.8, "contacts": 0, "lost": 0,
            "served_twice": 0}
    return base | extra


def by(rows: list[dict], case_part: str, metric: str) -> dict:
    hits = [r for r in rows if case_part in r["case"] and r["metric"] == metric]
    assert len(hits) == 1, (case_part, metric, hits)
    return hits[0]


def test_rows_compare_the_planner_with_the_baseline_and_3_robots_with_1() -> None:
    results = {(1, "insertion"): summary(30.0, 300.0), (1, "nearest_idle"): summary(20.0, 500.0),
               (3, "insertion"): summary(80.0, 100.0), (3, "nearest_idle"): summary(70.0, 110.0, contacts=1)}
    rows = bench.stream_rows(results, 6, 25.0, 0)
    one = by(rows, "1 robot", "wait s, mean")
    assert one["ours"] == pytest.approx(300.0) and one["reference"] == pytest.approx(500.0) and one["met"] is True
    three = by(rows, "3 robots", "wait s, mean")
    assert three["met"] is False                            # 100 > 0.8 x 110
    assert by(rows, "3 robots", "bumper contacts")["met"] is False      # the baseline's contact counts too
    assert by(rows, "1 robot", "orders served at their tables")["met"] is True
    ratio = by(rows, "3 robots / 1 robot", "ratio")
    assert ratio["ours"] == pytest.approx(80.0 / 30.0) and ratio["met"] is True


def test_a_failed_run_is_a_failed_row_not_a_crash() -> None:
    results = {(1, "insertion"): summary(30.0, 300.0, delivered=4, lost=2),
               (3, "insertion"): {"exit": 1, "orders": 6, "delivered": 0, "lost": 6, "served_twice": 0,
                                  "contacts": 0}}
    rows = bench.stream_rows(results, 6, 25.0, 0)
    assert by(rows, "1 robot", "orders served at their tables")["met"] is False
    assert by(rows, "1 robot", "orders lost or served twice")["ours"] == 2
    assert by(rows, "3 robots", "orders per hour")["ours"] is None
    assert not [r for r in rows if r["metric"] == "ratio"]            # no throughput of a failed run


def keep(run_dir: Path, settings: dict | None, summary_doc: dict | None) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    if settings is not None:
        (run_dir / "settings.json").write_text(json.dumps(settings))
    if summary_doc is not None:
        (run_dir / "fleet.json").write_text(json.dumps(summary_doc))


def test_a_kept_run_is_reused_only_with_the_same_settings_and_a_summary(tmp_path: Path) -> None:
    settings = bench.run_settings(3, "insertion", 30, 12.663255, 0)
    keep(tmp_path / "same", dict(settings, commit="abc1234"), {"summary": summary(80.0, 100.0)})
    kept = bench.kept_run(tmp_path / "same", settings)
    assert kept is not None and kept["commit"] == "abc1234"
    assert kept["orders_per_hour"] == pytest.approx(80.0)
    # the gap as fleet_demo was given it (to the millisecond) is the same gap
    assert bench.kept_run(tmp_path / "same", bench.run_settings(3, "insertion", 30, 12.6631, 0)) is not None
    for other in (bench.run_settings(3, "insertion", 30, 25.0, 0), bench.run_settings(3, "insertion", 30, 12.663, 1),
                  bench.run_settings(2, "insertion", 30, 12.663, 0),
                  bench.run_settings(3, "nearest_idle", 30, 12.663, 0),
                  bench.run_settings(3, "insertion", 6, 12.663, 0)):
        assert bench.kept_run(tmp_path / "same", other) is None, other
    keep(tmp_path / "unfinished", settings, None)                       # died before its summary
    keep(tmp_path / "unknown", None, {"summary": summary(80.0, 100.0)})  # made before settings were kept
    (tmp_path / "corrupt").mkdir()
    (tmp_path / "corrupt" / "settings.json").write_text("{not json")
    (tmp_path / "corrupt" / "fleet.json").write_text(json.dumps({"summary": summary(80.0, 100.0)}))
    keep(tmp_path / "gave_up", settings, {"summary": summary(80.0, 100.0, delivered=9, lost=21)})   # run again
    for name in ("unfinished", "unknown", "corrupt", "missing", "gave_up"):
        assert bench.kept_run(tmp_path / name, settings) is None, name


def test_fleet_sizes_from_the_environment() -> None:
    assert bench.fleet_sizes("") == (1, 2, 3)
    assert bench.fleet_sizes("3,1") == (1, 3)
    assert bench.fleet_sizes(" 2 ") == (2,)
    for bad in ("one", "0,3", "1.5"):
        with pytest.raises(ValueError, match="CHEFBOT_STREAM_FLEETS"):
            bench.fleet_sizes(bad)


def test_kept_only_reports_the_kept_runs_and_runs_nothing(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(bench, "ROOT", tmp_path)
    monkeypatch.setattr(bench, "run_stream", lambda *a: pytest.fail("KEPT_ONLY must not run the stream"))
    monkeypatch.setenv("CHEFBOT_STREAM_KEPT_ONLY", "1")
    monkeypatch.setenv("CHEFBOT_STREAM_FLEETS", "1,3")
    monkeypatch.setenv("CHEFBOT_STREAM_EVERY", "12.663")
    runs = tmp_path / "build" / "bench_fleet_stream"
    for robots, policy, per_hour in ((1, "insertion", 30.0), (1, "nearest_idle", 20.0), (3, "insertion", 80.0)):
        keep(runs / f"{robots}_{policy}", dict(bench.run_settings(robots, policy, 30, 12.663, 0), commit="abc"),
             {"summary": summary(per_hour, 100.0, orders=30, delivered=30)})
    rows = bench.run()
    assert by(rows, "3 robots / 1 robot", "ratio")["ours"] == pytest.approx(80.0 / 30.0)
    assert by(rows, "3 robots", "wait s, mean")["reference"] is None        # its baseline was not kept
    assert by(rows, "1 robot", "wait s, mean")["reference"] == pytest.approx(100.0)
