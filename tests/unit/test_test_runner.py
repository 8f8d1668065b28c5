"""The test runner's own logic: counting, parsing, leak detection, process-group shutdown."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"chefbot_tools_{name}", ROOT / "tools" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


run_tests = _load("run_tests")
procs = _load("procs")


def test_junit_counts_pass_fail_skip(tmp_path: Path) -> None:
    xml = tmp_path / "r.xml"
    xml.write_text(
        '<testsuites><testsuite name="s" tests="4">'
        '<testcase classname="a" name="ok"/>'
        '<testcase classname="a" name="bad"><failure message="x"/></testcase>'
        '<testcase classname="a" name="err"><error message="y"/></testcase>'
        '<testcase classname="a" name="sk"><skipped message="rviz not installed"/></testcase>'
        "</testsuite></testsuites>")
    t = run_tests.junit_totals(xml, "lbl")
    assert (t.passed, t.failed, t.skipped) == (1, 2, 1)
    assert "lbl::a.bad: x" in t.failures and "lbl::a.err: y" in t.failures   # with the reason
    assert t.skips == ["lbl::a.sk: rviz not installed"]  # the runner prints each skip's reason


def test_junit_failure_reason_is_the_first_line_of_message_or_text(tmp_path: Path) -> None:
    # rosunit writes the assertion into the element's text, with the traceback after it
    xml = tmp_path / "r.xml"
    xml.write_text('<testsuite tests="2"><testcase classname="c" name="t">'
                   '<failure type="AssertionError">\n0.70 not greater than 0.75\n  File "x.py", line 1</failure>'
                   '</testcase><testcase classname="c" name="u"><failure/></testcase></testsuite>')
    t = run_tests.junit_totals(xml, "lbl")
    assert t.failures == ["lbl::c.t: 0.70 not greater than 0.75", "lbl::c.u"]


def test_junit_failure_reason_keeps_the_tests_own_message_after_a_diff(tmp_path: Path) -> None:
    # assertEqual on strings: unittest's diff first, the test's own message after " : "
    xml = tmp_path / "r.xml"
    xml.write_text('<testsuite tests="1"><testcase classname="c" name="t"><failure type="AssertionError">\n'
                   "'ABORTED' != 'SUCCEEDED'\n- ABORTED\n+ SUCCEEDED\n : table_4: no plan\nmore</failure>"
                   '</testcase></testsuite>')
    t = run_tests.junit_totals(xml, "lbl")
    assert t.failures == ["lbl::c.t: 'ABORTED' != 'SUCCEEDED' : table_4: no plan"]


def test_junit_suite_error_without_cases_is_a_failure(tmp_path: Path) -> None:
    # rostest writes this when the test node never came up
    xml = tmp_path / "r.xml"
    xml.write_text('<testsuite name="s" tests="1" errors="1" failures="0"></testsuite>')
    t = run_tests.junit_totals(xml, "lbl")
    assert t.failed == 1 and t.passed == 0


def test_an_empty_or_torn_result_file_is_a_failure_not_a_crash(tmp_path: Path) -> None:
    # rosunit opens its file first: a test node killed before it finished leaves it empty or torn
    for text in ("", '<testsuite tests="1"><testcase classname="c" name="t"/>'):
        xml = tmp_path / "r.xml"
        xml.write_text(text)
        t = run_tests.junit_totals(xml, "lbl")
        assert (t.passed, t.failed) == (0, 1)
        assert "unreadable result file r.xml" in t.failures[0]


def test_junit_suite_error_beside_passing_cases_counts(tmp_path: Path) -> None:
    # rosunit: the test method passed, but the node then died (exit 1) -> errors="1"
    xml = tmp_path / "r.xml"
    xml.write_text('<testsuite errors="1" failures="0" tests="1">'
                   '<testcase classname="c" name="t"/></testsuite>')
    t = run_tests.junit_totals(xml, "lbl")
    assert (t.passed, t.failed) == (1, 1)


def test_count_line_pattern() -> None:
    m = run_tests._COUNT_LINE.search("firmware: 12 passed, 3 failed, 1 skipped")
    assert m and m.groups() == ("12", "3", "1")
    m = run_tests._COUNT_LINE.search("40 passed, 0 failed")
    assert m and m.groups() == ("40", "0", None)
    assert run_tests._COUNT_LINE.search("passed and failed") is None


def test_leak_detection_finds_and_misses_by_token() -> None:
    token = "leaktest" + str(os.getpid())
    env = dict(os.environ, CHEFBOT_TEST_RUN=token)
    p = subprocess.Popen(["sleep", "30"], env=env, start_new_session=True)
    try:
        deadline = time.monotonic() + 5
        found = []
        while time.monotonic() < deadline and not found:
            found = [pid for pid, _ in run_tests.leaked(token)]
            time.sleep(0.05)
        assert p.pid in found
        assert p.pid not in [pid for pid, _ in run_tests.leaked("some-other-token")]
    finally:
        procs.kill_group(p.pid)
        p.wait(timeout=5)
    assert run_tests.leaked(token) == []


def test_kill_group_stops_children_that_ignore_sigint() -> None:
    # a parent that ignores SIGINT with a child: both must be gone afterwards
    script = "trap '' INT; sleep 60 & wait"
    p = subprocess.Popen(["bash", "-c", script], start_new_session=True)
    time.sleep(0.2)  # let bash install the trap; the assertion below does not depend on timing
    procs.kill_group(p.pid, grace_int=0.5, grace_term=0.5)
    p.wait(timeout=5)
    assert not procs.group_alive(p.pid)


def test_kill_group_stops_descendants_in_their_own_session() -> None:
    # roslaunch starts each node with setsid: the node is outside roslaunch's group,
    # and an orphan once roslaunch is killed. A launcher that ignores INT and TERM
    # (killed) with such a child that ignores INT: the child must be gone too.
    script = "trap '' INT TERM; setsid bash -c \"trap '' INT; sleep 60\" & wait"
    p = subprocess.Popen(["bash", "-c", script], start_new_session=True)
    deadline = time.monotonic() + 10
    tree: dict[int, str] = {}
    while time.monotonic() < deadline and len(tree) < 2:  # bash and the setsid child
        tree = procs.group_tree(p.pid)
        time.sleep(0.05)
    assert len(tree) >= 2, tree
    outsiders = [pid for pid in tree if pid not in procs.group_members(p.pid)]
    assert outsiders, "the child should be in a session of its own"
    procs.kill_group(p.pid, grace_int=0.3, grace_term=0.3)
    p.wait(timeout=5)
    assert procs._survivors(tree) == []


def test_stop_children_stops_every_spawned_group_and_its_descendants() -> None:
    """An interrupt (Ctrl-C, a CI job's SIGTERM) cannot stop the runner's worker threads; it stops
    their children instead, each with what it started, and the threads then return by themselves."""
    script = "setsid bash -c \"trap '' INT; sleep 60\" & sleep 60 & wait"
    kids = [run_tests.spawn(["bash", "-c", script]) for _ in range(2)]
    trees: dict[int, str] = {}
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and len(trees) < 6:   # bash, setsid'd bash/sleep, sleep: x2
        trees = {pid: c for k in kids for pid, c in procs.group_tree(k.pid).items()}
        time.sleep(0.05)
    assert len(trees) >= 6, trees
    done = run_tests.spawn(["true"])
    done.wait(timeout=5)
    run_tests.forget(done)                       # a finished child is not stopped again
    assert {k.pid for k in kids} <= run_tests._LIVE and done.pid not in run_tests._LIVE
    try:
        run_tests.stop_children()
        for k in kids:
            k.wait(timeout=5)
        assert procs._survivors(trees) == []
    finally:
        for k in kids:
            procs.kill_group(k.pid, grace_int=0.1, grace_term=0.1)
            run_tests.forget(k)


def test_free_port_is_bindable() -> None:
    import socket
    port = procs.free_port()
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))


@pytest.fixture
def write_test(tmp_path: Path):
    """``write_test(name, body)``: a rostest file ``<launch>body</launch>`` in tmp_path."""
    def write(name: str, body: str) -> Path:
        f = tmp_path / f"{name}.test"
        f.write_text(f"<launch>{body}</launch>")
        return f
    return write


def test_sim_timed_follows_includes(tmp_path: Path, write_test) -> None:
    """A test runs in sim time when it or anything it includes mentions use_sim_time; an include
    that cannot be resolved counts as timed (the serial stage is the safe side)."""
    pkg = tmp_path / "pkg_a"
    (pkg / "launch").mkdir(parents=True)
    (pkg / "launch" / "sim.launch").write_text('<launch><param name="/use_sim_time" value="true"/></launch>')
    (pkg / "launch" / "plain.launch").write_text('<launch><node pkg="x" type="y" name="z"/></launch>')
    packages = {"pkg_a": pkg}

    assert not run_tests.sim_timed(write_test("plain", '<include file="$(find pkg_a)/launch/plain.launch"/>'),
                                   packages)
    assert run_tests.sim_timed(write_test("nested", '<include file="$(find pkg_a)/launch/plain.launch"/>'
                                          '<include file="$(find pkg_a)/launch/sim.launch" />'), packages)
    assert run_tests.sim_timed(write_test("own", '<param name="use_sim_time" value="true"/>'), packages)
    assert run_tests.sim_timed(write_test("arg", '<include file="$(find pkg_a)/launch/$(arg which)"/>'), packages)
    assert run_tests.sim_timed(write_test("other", '<include file="$(find rviz)/launch/x.launch"/>'), packages)
    (tmp_path / "local.launch").write_text("<launch/>")
    assert not run_tests.sim_timed(write_test("dirname", '<include file="$(dirname)/local.launch"/>'), packages)


def test_sim_timed_knows_the_workspace_tests() -> None:
    """The simulator's tests are timed; a serial-driver test on a pty is not."""
    by_name = {f.stem: f for _, f in run_tests.rostest_files()}
    assert run_tests.sim_timed(by_name["delivery_route_firmware"])
    assert run_tests.sim_timed(by_name["slam_workflow"])
    assert run_tests.sim_timed(by_name["fleet_netns"])       # the hosts' launches run the simulator
    assert not run_tests.sim_timed(by_name["diff_drive"])


def test_a_rostest_declaring_a_long_time_limit_gets_it_and_runs_last(write_test) -> None:
    """The runner's wall timeout follows the file's own time-limit (plus launch and shutdown time), never
    below the default; a file declaring more than the default is a long one (run after the unit tests)."""
    default = run_tests.ROSTEST_TIMEOUT_S
    short = write_test("short", '<test test-name="a" pkg="p" type="t.py" time-limit="420"/>')
    none = write_test("none", '<test test-name="a" pkg="p" type="t.py"/>')
    long_ = write_test("long", '<test test-name="a" pkg="p" type="t.py" time-limit="60"/>\n'
                       f'<test time-limit = "{default + 900:.0f}" test-name="b" pkg="p" type="u.py"/>')
    assert run_tests.time_limit(short) == 420.0 and run_tests.time_limit(none) == 60.0
    assert run_tests.wall_timeout(short) == max(default, 540.0)
    assert run_tests.wall_timeout(long_) == default + 1020.0
    assert not run_tests.is_long(short) and not run_tests.is_long(none) and run_tests.is_long(long_)


def test_stop_tracked_stops_a_node_its_launcher_left_behind() -> None:
    # the launcher ends by itself (as roslaunch does after a failure) before its setsid child does
    script = "setsid bash -c \"trap '' INT; sleep 60\" & sleep 0.5"
    p = subprocess.Popen(["bash", "-c", script], start_new_session=True)
    tracked: dict[int, str] = {}
    while p.poll() is None:
        tracked.update(procs.group_tree(p.pid))
        time.sleep(0.02)
    orphans = procs._survivors(tracked)
    assert orphans, "the child should outlive its launcher"
    procs.stop_tracked(tracked, grace_term=0.5)
    assert procs._survivors(tracked) == []


def _fake_runs(monkeypatch, outcomes: dict[str, list[bool]]) -> list[tuple[str, int]]:
    """run_rostest replaced: each file passes or fails by its list of outcomes, run after run."""
    calls: list[tuple[str, int]] = []

    def fake(env, pkg, test, run=1):
        calls.append((test.stem, run))
        ok = outcomes[test.stem][run - 1]
        return run_tests.Totals(passed=int(ok), failed=int(not ok),
                                failures=[] if ok else [f"{pkg}/{test.stem}: run {run} failed"])
    monkeypatch.setattr(run_tests, "run_rostest", fake)
    return calls


def test_a_failed_rostest_runs_again_at_the_end_and_only_the_last_run_counts(monkeypatch) -> None:
    calls = _fake_runs(monkeypatch, {"steady": [True], "flaky": [False, True], "broken": [False, False]})
    r = run_tests.Retries({}, 1)
    total = run_tests.Totals()
    for stem in ("steady", "flaky", "broken"):
        total.add(r.first("pkg", Path(f"/x/{stem}.test")))
    assert (total.passed, total.failed) == (1, 0)       # the failed ones wait for their second run
    total.add(r.finish())
    assert (total.passed, total.failed) == (2, 1)
    assert total.failures == ["pkg/broken: run 2 failed"]
    assert calls == [("steady", 1), ("flaky", 1), ("broken", 1), ("flaky", 2), ("broken", 2)]
    assert [n.split(":")[0] for n in r.notes] == ["RETRIED pkg/flaky", "RETRIED pkg/broken"]
    assert "passed on run 2; the first run: pkg/flaky: run 1 failed" in r.notes[0]
    assert "failed again on run 2" in r.notes[1]


def test_no_retries_counts_the_first_failure(monkeypatch) -> None:
    _fake_runs(monkeypatch, {"flaky": [False, True]})
    r = run_tests.Retries({}, 0)
    t = r.first("pkg", Path("/x/flaky.test"))
    assert (t.passed, t.failed) == (0, 1)
    assert (r.finish().failed, r.notes) == (0, [])


@pytest.mark.parametrize("raw, runs", [("", 1), ("0", 0), ("2", 2), ("x", 1), ("-1", 1)])
def test_retries_setting(monkeypatch, raw: str, runs: int) -> None:
    monkeypatch.setenv("CHEFBOT_TEST_RETRIES", raw)
    assert run_tests.rostest_retries() == runs


def test_sim_stage_one_at_a_time_beside_stage_3_then_side_by_side_long_ones_last(monkeypatch, write_test) -> None:
    """Stage 2: while stage 3 runs, one short sim-time rostest at a time and no long one; after it, two at
    a time, the long ones (longest first) among them."""
    import threading

    long_limit = run_tests.ROSTEST_TIMEOUT_S + 600
    files = {n: write_test(n, f'<test test-name="a" pkg="p" type="t.py" time-limit="{lim:.0f}"/>')
             for n, lim in (("s1", 60), ("s2", 60), ("s3", 60), ("s4", 60), ("l1", long_limit),
                            ("l2", long_limit + 100))}
    stage3 = threading.Event()
    lock, running, log = threading.Lock(), [0], []
    both = threading.Barrier(2, timeout=30.0)     # the first two runs after stage 3 must overlap

    def fake(env, pkg, test, run=1):
        with lock:
            running[0] += 1
            log.append((test.stem, running[0], stage3.is_set()))
            after = sum(1 for e in log if e[2])
        if 1 <= after <= 2:
            both.wait()
        with lock:
            running[0] -= 1
            if len(log) == 2:
                stage3.set()                       # stage 3 ends after two short tests
        return run_tests.Totals(passed=1)

    monkeypatch.setattr(run_tests, "run_rostest", fake)
    total = run_tests.run_sim_stage([("p", f) for f in files.values()], run_tests.Retries({}, 0), stage3, 2)
    assert total.passed == 6
    before = [e for e in log if not e[2]]
    assert len(before) == 2 and all(n.startswith("s") and k == 1 for n, k, _ in before)   # one short at a time
    assert max(k for _, k, _ in log) == 2                                                 # then two side by side
    longs = [n for n, _, _ in log if n.startswith("l")]
    assert longs == ["l2", "l1"]                                                 # longest time-limit first


@pytest.mark.parametrize("raw, jobs", [("", 2), ("1", 1), ("3", 3), ("x", 2), ("0", 2)])
def test_sim_jobs_setting(monkeypatch, raw: str, jobs: int) -> None:
    monkeypatch.setenv("CHEFBOT_SIM_JOBS", raw)
    assert run_tests.sim_jobs() == jobs
