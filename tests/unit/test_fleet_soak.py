"""tools/fleet_soak.py's pure parts: the fault schedule, judging order histories, memory growth, restart
detection, the checks and the report."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from fleet_soak import (
    MIN_FIT_SPAN_S,
    charges_completed,
    checks,
    fault_schedule,
    growth_mb_per_h,
    judge_orders,
    memory_table,
    record_states,
    render_report,
    restarts_by_others,
    sim_battery,
    start_socs,
)

NAMES = ["chefbot1", "chefbot2", "chefbot3"]


def test_the_faults_are_two_kills_of_one_robot_and_one_of_the_dispatcher_at_fixed_fractions() -> None:
    f = fault_schedule(7200.0, NAMES, seed=0)
    assert [x["kind"] for x in f] == ["robot", "dispatcher", "robot"]
    assert [x["at"] for x in f] == [1800.0, 3240.0, 4320.0]
    assert f[0]["target"] == f[2]["target"] in NAMES and f[1]["target"] == "/fleet/dispatcher"
    assert f == fault_schedule(7200.0, NAMES, seed=0)
    assert {fault_schedule(100.0, NAMES, s)[0]["target"] for s in range(20)} == set(NAMES)   # seeded choice
    with pytest.raises(ValueError):
        fault_schedule(0.0, NAMES, 0)


def test_the_batteries_scale_with_the_run_so_every_robot_charges_within_it_one_after_another() -> None:
    for hours in (0.5, 2.0, 8.0):
        b = sim_battery(hours, NAMES)
        socs = [b["robot_options"][n]["battery_initial_soc"] for n in NAMES]
        assert len(set(socs)) == len(NAMES)           # not all at the charger at once
        for soc in socs:
            drain_h = (soc - 0.25) * b["battery_capacity_ah"] / 3.0      # ~3 A drawn
            charge_h = (0.9 - 0.25) * b["battery_capacity_ah"] / (b["charge_current"] - 2.5)
            assert drain_h + charge_h < 0.6 * hours, (hours, soc)
    for hours in (0.05, 0.15, 2.0):     # the last 25 % carries a robot through a trip (~200 s at 3.5 A)
        assert 0.25 * sim_battery(hours, NAMES)["battery_capacity_ah"] >= 200 * 3.5 / 3600, hours
    assert start_socs(sim_battery(2.0, NAMES[:2])) == f"{NAMES[0]} 40%, {NAMES[1]} 55%"
    assert start_socs({"battery_initial_soc": 0.4}) == "40%"      # a report of an older run


def test_state_changes_are_recorded_once_each() -> None:
    h: dict = {}
    record_states(h, [("o1", "queued", ""), ("o2", "assigned", "")], 1.0)
    record_states(h, [("o1", "queued", ""), ("o2", "assigned", "")], 2.0)      # the periodic re-publication
    record_states(h, [("o1", "assigned", ""), ("o2", "served", "")], 3.0)
    assert h == {"o1": [("queued", "", 1.0), ("assigned", "", 3.0)],
                 "o2": [("assigned", "", 1.0), ("served", "", 3.0)]}


def test_every_order_is_served_failed_with_a_reason_lost_or_duplicated() -> None:
    placed = {"o1": 0.0, "o2": 1.0, "o3": 2.0, "o4": 3.0, "o5": 4.0, "o6": 5.0, "o7": 6.0}
    h = {"o1": [("queued", "", 0.5), ("on_the_way", "", 10.0), ("served", "", 40.0)],
         "o2": [("assigned", "", 2.0), ("queued", "chefbot2 offline", 5.0),
                ("failed", "no robot reaches table_9", 9.0)],
         "o3": [("assigned", "", 3.0), ("on_the_way", "", 20.0)],                            # never final: lost
         "o4": [("on_the_way", "", 4.0), ("served", "", 30.0), ("on_the_way", "", 31.0), ("served", "", 50.0)],
         "o5": [("cancelled", "", 6.0)],                                                      # no reason
         "o7": [("cancelled", "guest left", 6.0), ("on_the_way", "", 8.0)]}                     # revived
    j = judge_orders(placed, h)
    assert (j["placed"], j["served"], j["failed"], j["cancelled"]) == (7, 2, 1, 2)
    assert j["lost"] == ["o3", "o6"] and j["duplicated"] == ["o4", "o7"] and j["no_reason"] == ["o5"]
    assert j["reasons"] == {"no robot reaches table_9": 1, "guest left": 1} and j["final_s"]["o1"] == 40.0


def test_memory_growth_is_the_fitted_slope_per_hour_after_the_warm_up() -> None:
    flat = [(t, 50e6) for t in range(0, 3600, 10)]
    assert growth_mb_per_h(flat)[0] == pytest.approx(0.0, abs=1e-9)
    leak = [(t, 50e6 + 2e6 * t / 3600.0) for t in range(0, 3600, 10)]      # 2 MB per hour
    g, span = growth_mb_per_h(leak)
    assert g == pytest.approx(2.0) and span == 3590
    startup = [(t, 20e6 if t < 100 else 50e6) for t in range(0, 3600, 10)]   # grows while starting, then flat
    assert growth_mb_per_h(startup)[0] > 1.0 and growth_mb_per_h(startup, warmup_s=100.0)[0] == pytest.approx(0.0)
    assert growth_mb_per_h([(0.0, 1.0), (1.0, 2.0)]) == (None, 0.0)


def test_a_pid_change_is_by_the_test_only_when_the_test_killed_that_node_then() -> None:
    series = {"/chefbot2/amcl": [(0.0, 100, 1e6), (10.0, 100, 1e6), (20.0, None, None), (30.0, 200, 1e6)],
              "/chefbot1/amcl": [(0.0, 101, 1e6), (10.0, 101, 1e6), (20.0, 301, 1e6)],          # respawned alone
              "/fleet/dispatcher": [(0.0, 102, 1e6), (10.0, 102, 1e6), (20.0, 302, 1e6)],
              "/traffic": [(0.0, 103, 1e6), (10.0, 103, 1e6), (20.0, None, None)],               # vanished
              "/map_server": [(0.0, 104, 1e6), (20.0, 104, 1e6)]}
    kills = [(15.0, "/chefbot2/"), (12.0, "/fleet/dispatcher")]
    got = {(r["node"], r["what"].split()[0]) for r in restarts_by_others(series, kills)}
    assert got == {("/chefbot1/amcl", "pid"), ("/traffic", "vanished")}
    # the same dispatcher restart with no kill of the test: someone else's
    assert {r["node"] for r in restarts_by_others(series, [(15.0, "/chefbot2/")])} == \
        {"/chefbot1/amcl", "/traffic", "/fleet/dispatcher"}
    # a kill long before the change does not explain it
    assert "/chefbot2/amcl" in {r["node"] for r in restarts_by_others(series, [(1.0, "/chefbot2/")])}


def test_the_memory_table_fits_each_node_over_its_longest_run() -> None:
    series = {"/a": [(float(t), 7 if t < 50 else 8, 10e6 + (t * 1e6 if t < 50 else 0)) for t in range(0, 400, 10)]}
    row = memory_table(series, warmup_s=0.0)[0]
    assert row["runs"] == 2 and row["growth_mb_h"] == pytest.approx(0.0) and row["rss_start_mb"] == 10.0


def test_charges_count_charging_then_back_in_service() -> None:
    states = [("idle", "", 0), ("to_charger", "battery 24 %", 1), ("charging", "battery 24 %", 2),
              ("idle", "", 3), ("charging", "", 4), ("offline", "", 5)]
    assert charges_completed(states) == 1


def _doc(**over) -> dict:
    doc = {"orders": judge_orders({"o1": 0.0}, {"o1": [("served", "", 9.0)]}), "not_accepted": [], "served_away": [],
           "faults": [{"kind": "robot", "target": "chefbot2", "at": 10.0, "recovered": True, "detected_s": 10.5,
                       "recovery_s": 20.0, "detail": "x"}],
           "charges_completed": 1, "charges": {"chefbot2": 1}, "battery_min": {"chefbot2": 0.24},
           "memory": [{"node": "/a", "runs": 1, "rss_start_mb": 10.0, "rss_end_mb": 10.1, "growth_mb_h": 0.1,
                       "fit_span_s": MIN_FIT_SPAN_S}],
           "restarts_by_others": [], "meta": {"date_utc": "2026-12-01 20:00", "commit": "abc"}, "robots": 3,
           "names": NAMES, "seed": 0, "sim_hours": 2.0, "sim_seconds": 7200.0, "drain_seconds": 60.0,
           "wall_seconds": 8000.0, "rtf_asked": "1.0", "rtf_achieved": 0.9, "order_every_s": 30.0,
           "battery": sim_battery(2.0, NAMES), "summary": {"orders_per_hour": 40.0, "wait_median_s": 100.0,
                                                    "wait_p95_s": 300.0},
           "contacts": {"chefbot1": 0}, "sample_every_s": 10.0, "warmup_s": 300.0}
    doc.update(over)
    return doc


def test_the_checks_fail_on_each_kind_of_fault() -> None:
    assert all(c["ok"] for c in checks(_doc()))
    bad = {"lost": _doc(orders=judge_orders({"o1": 0.0}, {})),
           "fault": _doc(faults=[{"kind": "robot", "target": "chefbot2", "at": 10.0}]),
           "charge": _doc(charges_completed=0),
           "memory": _doc(memory=[{"node": "/a", "runs": 1, "rss_start_mb": 1.0, "rss_end_mb": 90.0,
                                   "growth_mb_h": 45.0, "fit_span_s": MIN_FIT_SPAN_S}]),
           "restart": _doc(restarts_by_others=[{"node": "/a", "what": "pid 1 -> 2", "at": 3.0}])}
    for what, doc in bad.items():
        assert not all(c["ok"] for c in checks(doc)), what
    # a fast-growing node over a short fit is reported, not judged
    short = _doc(memory=[{"node": "/a", "runs": 1, "rss_start_mb": 1.0, "rss_end_mb": 9.0, "growth_mb_h": 45.0,
                          "fit_span_s": 60.0}])
    assert all(c["ok"] for c in checks(short))


def test_the_report_states_the_run_and_says_when_it_was_short() -> None:
    doc = _doc()
    doc["checks"] = checks(doc)
    text = render_report(doc)
    assert "**PASSED**" in text and "`/a`" in text and "+0.10" in text and "short check" not in text
    doc = _doc(sim_hours=0.15)
    doc["checks"] = checks(doc)
    assert "A short check (0.15 h" in render_report(doc)
