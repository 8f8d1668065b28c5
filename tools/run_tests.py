#!/usr/bin/env python3
"""Run every test of the workspace and print one closing line of totals.

Runners:
  1. the rostest files (``*/test/*.test`` and ``tests/test/*.test``) that run
     in no sim time (error handling, the serial
     driver on a pty, map_server ...): side by side, as many at once as the
     machine has cores (CHEFBOT_TEST_JOBS overrides);
  2. the rostests that run in sim time (the test or a launch file it includes
     mentions ``use_sim_time``: a simulator paced against the wall clock): one
     at a time while stage 3 runs beside them, then CHEFBOT_SIM_JOBS (default
     2) at a time once stage 3 has finished; the long ones (a ``time-limit``
     over the runner's timeout: the delivery routes, the hotel SLAM workflow,
     ...) only then, longest first.  The tests judge in sim time, so a
     simulator slowed by its neighbour only takes longer;
  3. ``make -C firmware test`` with a bounded fuzz run, then pytest over every
     ``*/test/unit`` directory and ``tests/unit``: from the start, one at a
     time at the lowest CPU priority (``nice 19``) beside stages 1 and 2.
     None of them is timed.  A simulator rostest keeps about one core of two
     busy; these take the rest, and the scheduler gives the simulator's
     processes the CPU whenever they want it.  Without a sim-time rostest to
     run beside (``--only unit``, ``-k`` selecting none), they run in stage 1's
     pool at normal priority instead.
Each rostest gets its own master on a free port (rostest's default) and its
own process group, killed afterwards: after CHEFBOT_ROSTEST_TIMEOUT (600 s) or,
when the file declares a longer ``time-limit``, 120 s after that.

A rostest file that fails is run once more at the end, alone (CHEFBOT_TEST_RETRIES, default 1; 0 =
never): the simulator tests drive real processes against a clock on a shared machine, and a few
(SLAM's live map of the hotel, amcl's recovery from a kidnap) have a measured tail of failures.  Only
the second run counts; each retried file is named, with its first failure, in a ``RETRIED`` line
before the totals, so a flaky test stays visible.

Every child gets the environment variable CHEFBOT_TEST_RUN=<token>; at the end
any process still carrying it is reported as a leak, killed, and counted as a
failure.  The last line printed is ``N passed, M failed, K skipped``; the exit
code is non-zero when anything failed or nothing ran.

Usage (inside the workspace environment, see tools/env.sh):
    python tools/run_tests.py [--only unit|firmware|rostest] [-k PATTERN]
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import uuid
import xml.etree.ElementTree as ET
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from procs import kill_group, stop_on_sigterm

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "build" / "test_results"
ROSTEST_TIMEOUT_S = float(os.environ.get("CHEFBOT_ROSTEST_TIMEOUT", "600"))
RETRIES_DEFAULT = 1     # runs more of a failed rostest file (CHEFBOT_TEST_RETRIES)
FUZZ_SECONDS = os.environ.get("FUZZ_SECONDS", "60")
UNIT_NICE = 19      # stage 3's CPU priority beside the simulator rostests (19 = the lowest)
SKIP_DIRS = {".git", ".venv", "build", "devel", "install", "node_modules"}


@dataclass
class Totals:
    passed: int = 0
    failed: int = 0
    skipped: int = 0
    failures: list[str] = field(default_factory=list)
    skips: list[str] = field(default_factory=list)  # "test: reason", printed by the runner

    def add(self, other: Totals) -> None:
        self.passed += other.passed
        self.failed += other.failed
        self.skipped += other.skipped
        self.failures += other.failures
        self.skips += other.skips


_PRINT = threading.Lock()   # the unit stage's runners print from several threads


def log(msg: str) -> None:
    with _PRINT:
        print(f"[test] {msg}", flush=True)


def show(text: str) -> None:
    with _PRINT:
        print(text, flush=True)


def junit_totals(path: Path, label: str) -> Totals:
    """Count test cases in a JUnit XML file (pytest's, rosunit's, rostest's).

    A suite may declare more errors/failures than it has failing cases (rosunit
    reports an exception outside a test method, or a crashed test node, only in
    the suite's ``errors`` attribute): the difference counts as failures.  A file that is not XML (a
    test node killed while rosunit wrote it, or before) is one failure naming the file.
    """
    t = Totals()
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        return Totals(failed=1, failures=[f"{label}: unreadable result file {path.name} ({e}): the test "
                                          "process died before it finished writing it"])
    suites = [root] if root.tag == "testsuite" else list(root.iter("testsuite"))
    for suite in suites:
        failed_here = 0
        for case in suite.iter("testcase"):
            name = f"{label}::{case.get('classname', '')}.{case.get('name', '')}"
            if (bad := case.find("failure")) is not None or (bad := case.find("error")) is not None:
                t.failed += 1
                failed_here += 1
                reason = failure_reason(bad)
                t.failures.append(f"{name}: {reason}" if reason else name)
            elif (skip := case.find("skipped")) is not None:
                t.skipped += 1
                t.skips.append(f"{name}: {skip.get('message', '')}")
            else:
                t.passed += 1
        declared = int(suite.get("errors", 0) or 0) + int(suite.get("failures", 0) or 0)
        if declared > failed_here:
            t.failed += declared - failed_here
            t.failures.append(f"{label}: {declared - failed_here} error(s) outside test cases in {path.name}")
    return t


def failure_reason(el: ET.Element, limit: int = 300) -> str:
    """The first line of a JUnit <failure>/<error>: its message, else its text (for the closing FAILED
    lines, which CI's log tail shows when a test's own output has scrolled away).  When unittest put
    the test's own message after a multi-line diff (``'A' != 'B'`` / ``- A`` / ``+ B`` / `` : msg``),
    that message's first line is added: it is the one that says why."""
    for text in (el.get("message"), el.text):
        lines = [ln.strip() for ln in (text or "").splitlines() if ln.strip()]
        if lines:
            first = lines[0]
            own = next((ln for ln in lines[1:] if ln.startswith(": ")), None)
            if own is not None and own not in first:
                first += " " + own
            return first[:limit]
    return ""


_LIVE: set[int] = set()     # the runners' children's process groups, for an interrupt to stop
_LIVE_LOCK = threading.Lock()


def spawn(cmd: list[str], **kwargs) -> subprocess.Popen:
    """Popen in a new session, its group recorded until ``forget``."""
    proc = subprocess.Popen(cmd, start_new_session=True, **kwargs)
    with _LIVE_LOCK:
        _LIVE.add(proc.pid)
    return proc


def forget(proc: subprocess.Popen) -> None:
    with _LIVE_LOCK:
        _LIVE.discard(proc.pid)


def stop_children() -> None:
    """Stop every running child's group (an interrupt or SIGTERM: the worker threads cannot be
    interrupted, but they return once their child is gone)."""
    with _LIVE_LOCK:
        groups = sorted(_LIVE)
    for pgid in groups:
        kill_group(pgid, grace_int=2.0, grace_term=2.0)


def abandon(pool: ThreadPoolExecutor | None) -> None:
    """On an interrupt: drop the pool's queued jobs and stop every running child (``stop_children``)."""
    if pool is not None:
        pool.shutdown(wait=False, cancel_futures=True)
    stop_children()


def niced(cmd: list[str], nice: int) -> list[str]:
    """cmd run at CPU priority ``nice`` (0: as it is)."""
    return ["nice", "-n", str(nice), *cmd] if nice else cmd


def run_group(cmd: list[str], env: dict, timeout: float, log_path: Path, cwd: Path = ROOT) -> tuple[int, bool]:
    """Run cmd in a new session; stream output to log_path; kill the whole group afterwards.

    Returns (returncode, timed_out).
    """
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, "wb") as out:
        proc = spawn(cmd, cwd=cwd, env=env, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        timed_out = False
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            timed_out = True
            rc = -1
        except KeyboardInterrupt:
            kill_group(proc.pid)
            raise
        kill_group(proc.pid)
        if timed_out:
            proc.wait()
        forget(proc)
    return rc, timed_out


def tail(path: Path, n: int = 30) -> str:
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join("    " + line for line in lines[-n:])


def figures(out_dir: Path) -> str:
    """The ``[figure]`` lines the test nodes printed (their measurements; rostest keeps a node's
    stdout in its rosunit result), so a run's record keeps them."""
    lines = []
    for xml in sorted(out_dir.glob("**/rosunit-*.xml")):
        try:
            root = ET.parse(xml).getroot()
        except (ET.ParseError, OSError):
            continue
        for out in root.iter("system-out"):
            lines += [ln.strip() for ln in (out.text or "").splitlines() if ln.lstrip().startswith("[figure]")]
    return "\n".join("    " + line for line in lines)


# ----------------------------------------------------------------- discovery
def package_dirs() -> list[Path]:
    return sorted(p.parent for p in ROOT.glob("*/package.xml"))


def unit_dirs() -> list[Path]:
    return [d for d in sorted(ROOT.glob("*/test/unit")) + [ROOT / "tests" / "unit"] if d.is_dir()]


def package_name(pkg_dir: Path) -> str:
    """The package's name from its package.xml (the directory's name if it has none)."""
    return ET.parse(pkg_dir / "package.xml").getroot().findtext("name") or pkg_dir.name


def rostest_files() -> list[tuple[str, Path]]:
    found = []
    for pkg_dir in package_dirs():
        name = package_name(pkg_dir)
        for test in sorted(pkg_dir.glob("test/*.test")) + sorted(pkg_dir.glob("test/rostest/*.test")):
            found.append((name, test))
    return found


_INCLUDE = re.compile(r"""<include\s[^>]*?file\s*=\s*["']([^"']+)["']""")
_FIND = re.compile(r"^\$\(find ([\w-]+)\)(/.*)$")


def sim_timed(test: Path, packages: dict[str, Path] | None = None, _seen: set | None = None) -> bool:
    """Whether a launch/test file runs in sim time: it, or a file it includes, mentions
    ``use_sim_time``.  An include it cannot resolve (an argument in the path, another
    workspace's package) counts as timed: the serial stage is the safe side."""
    if packages is None:
        packages = {package_name(d): d for d in package_dirs()}
    seen = _seen if _seen is not None else set()
    if test in seen:
        return False
    seen.add(test)
    try:
        text = test.read_text()
    except OSError:
        return True
    if "use_sim_time" in text:
        return True
    for ref in _INCLUDE.findall(text):
        if ref.startswith("$(dirname)"):
            target = test.parent / ref[len("$(dirname)"):].lstrip("/")
        elif (m := _FIND.match(ref)) and m.group(1) in packages and "$(" not in m.group(2):
            target = packages[m.group(1)] / m.group(2).lstrip("/")
        else:
            return True
        if sim_timed(target, packages, seen):
            return True
    return False


# ----------------------------------------------------------------- runners
def unit_jobs() -> int:
    """CHEFBOT_TEST_JOBS (unit suites side by side), default one per core; a bad value is said and ignored."""
    raw = os.environ.get("CHEFBOT_TEST_JOBS", "")
    try:
        jobs = int(raw) if raw.strip() else 0
    except ValueError:
        print(f"[test] CHEFBOT_TEST_JOBS={raw!r} is not a whole number: using one job per core", flush=True)
        jobs = 0
    return max(1, jobs or os.cpu_count() or 1)


def pytest_dir(env: dict, d: Path, pattern: str | None, nice: int = 0) -> Totals:
    """One pytest run in one unit-test directory (at CPU priority ``nice``).

    Separate runs, each with the directory as rootdir and cwd: with one run over
    several directories the rootdir becomes the repository top, and pytest's
    importlib mode then names a test module ``chefbot_bringup.test.unit.test_x``,
    registering a dummy ``chefbot_bringup`` that shadows the real package.
    """
    rel = d.relative_to(ROOT)
    xml = RESULTS / "pytest" / (str(rel).replace("/", "-") + ".xml")
    xml.parent.mkdir(parents=True, exist_ok=True)
    if xml.exists():
        xml.unlink()
    cmd = niced([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--import-mode=importlib",
                 "--rootdir", str(d), f"--junitxml={xml}", "-o", "junit_family=xunit2", str(d)], nice)
    if pattern:
        cmd += ["-k", pattern]
    t0 = time.monotonic()
    proc = spawn(cmd, cwd=d, env=dict(env, QT_QPA_PLATFORM="offscreen"), stdin=subprocess.DEVNULL,
                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stdout, stderr = proc.communicate()
    forget(proc)
    if proc.returncode == 5:  # pytest: no tests collected (e.g. -k selected none here)
        return Totals()
    if not xml.exists():
        t = Totals(failed=1, failures=[f"pytest {rel} crashed (exit {proc.returncode})"])
    else:
        t = junit_totals(xml, f"pytest {rel}")
    lines = [f"[test] pytest {rel}: {t.passed} passed, {t.failed} failed, {t.skipped} skipped "
             f"({time.monotonic() - t0:.1f} s)"]
    lines += [f"[test]   skipped {skip}" for skip in t.skips]
    if t.failed or proc.returncode not in (0, 1):
        lines += [stdout[-6000:], stderr[-3000:]]
    show("\n".join(lines))
    return t


def sorted_unit_dirs(unit: bool) -> list[Path]:
    """The pytest directories, the one with the most test code first (so a pool does not end on one long job)."""
    dirs = unit_dirs() if unit else []
    if unit and not dirs:
        log("pytest: no unit test directories")
    dirs.sort(key=lambda d: -sum(f.stat().st_size for f in d.glob("test_*.py")))
    return dirs


def run_side_stage(env: dict, firmware: bool, rostests: list[tuple[str, Path]],
                   dirs: list[Path], pattern: str | None, retries: Retries) -> Totals:
    """Stage 1: the firmware's tests and the rostests that run in no sim time (and, when
    nothing runs beside stage 2, the pytest directories), side by side: none of them is paced
    against the wall clock."""
    total = Totals()
    jobs = unit_jobs()
    if firmware or rostests or dirs:
        log(f"stage 1: {len(dirs)} pytest director{'y' if len(dirs) == 1 else 'ies'}"
            f"{' + firmware' if firmware else ''} + {len(rostests)} rostest(s) in no sim time, {jobs} at a time")
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        futures = ([pool.submit(run_firmware, env)] if firmware else [])
        futures += [pool.submit(pytest_dir, env, d, pattern) for d in dirs]
        futures += [pool.submit(retries.first, pkg, test) for pkg, test in rostests]
        try:
            for fut in futures:
                total.add(fut.result())
        except BaseException:
            abandon(pool)
            raise
    return total


_COUNT_LINE = re.compile(r"(\d+) passed, (\d+) failed(?:, (\d+) skipped)?\s*$")


def run_firmware(env: dict, nice: int = 0) -> Totals:
    """The firmware's host unit tests, then a fuzz run of FUZZ_SECONDS (at CPU priority ``nice``)."""
    fw = ROOT / "firmware"
    t = Totals()
    if not (fw / "Makefile").exists():
        log("firmware: no Makefile yet, skipped")
        return t
    # the sanitizer builds need ASan first in the library list; the loopback-bind shim that
    # tools/env.sh preloads for ROS processes is not wanted there (no sockets are opened)
    env = {k: v for k, v in env.items() if k != "LD_PRELOAD"}
    log("firmware: host unit tests")
    logf = RESULTS / "firmware_test.log"
    rc, to = run_group(niced(["make", "-s", "-C", str(fw), "test"], nice), env, 900, logf)
    counts = None
    for line in logf.read_text(errors="replace").splitlines():
        m = _COUNT_LINE.search(line)
        if m:
            counts = m
    if counts:
        t.passed += int(counts.group(1))
        t.failed += int(counts.group(2))
        t.skipped += int(counts.group(3) or 0)
        if int(counts.group(2)):
            t.failures.append("firmware unit tests")
    if rc != 0 and not t.failed:
        t.failed += 1
        t.failures.append(f"firmware: make test exit {rc}{' (timeout)' if to else ''}")
    if rc != 0 or t.failed:
        show(tail(logf))
    log(f"firmware: {t.passed} passed, {t.failed} failed")

    if os.environ.get("CHEFBOT_SKIP_FUZZ") == "1":
        log("firmware: fuzz skipped (CHEFBOT_SKIP_FUZZ=1)")
        t.skipped += 1
        return t
    log(f"firmware: fuzz for {FUZZ_SECONDS} s")
    logf = RESULTS / "firmware_fuzz.log"
    rc, to = run_group(niced(["make", "-s", "-C", str(fw), "fuzz", f"FUZZ_SECONDS={FUZZ_SECONDS}"], nice), env,
                       float(FUZZ_SECONDS) * 4 + 300, logf)
    if rc == 0:
        t.passed += 1
    else:
        t.failed += 1
        t.failures.append(f"firmware fuzz exit {rc}{' (timeout)' if to else ''}: see {logf}")
        show(tail(logf))
    return t


def select_rostests(pattern: str | None) -> tuple[list[tuple[str, Path]], list[tuple[str, Path]]]:
    """The rostest files (``-k``: a substring of the path), split into (sim-timed, the others)."""
    tests = [(p, f) for p, f in rostest_files() if not pattern or pattern in str(f)]
    packages = {package_name(d): d for d in package_dirs()}     # read once for all the tests
    timed = [(p, f) for p, f in tests if sim_timed(f, packages)]
    return timed, [t for t in tests if t not in timed]


_TIME_LIMIT = re.compile(r"""<test\s[^>]*?time-limit\s*=\s*["']([\d.]+)["']""")


def time_limit(test: Path) -> float:
    """The longest ``time-limit`` (s) a rostest file declares for its test nodes (rostest's default: 60)."""
    limits = [float(v) for v in _TIME_LIMIT.findall(test.read_text(errors="replace"))]
    return max(limits, default=60.0)


def wall_timeout(test: Path) -> float:
    """How long the runner lets a rostest file run: its own time-limit and 120 s for the launch and the
    shutdown, at least CHEFBOT_ROSTEST_TIMEOUT."""
    return max(ROSTEST_TIMEOUT_S, time_limit(test) + 120.0)


def sim_jobs() -> int:
    """CHEFBOT_SIM_JOBS (sim-time rostests side by side once stage 3 is done), default 2; a bad value is said
    and ignored."""
    raw = os.environ.get("CHEFBOT_SIM_JOBS", "").strip()
    try:
        n = int(raw) if raw else 2
    except ValueError:
        n = 0
    if n < 1:
        log(f"CHEFBOT_SIM_JOBS={raw!r} is not a whole number >= 1: using 2")
        n = 2
    return n


def run_sim_stage(tests: list[tuple[str, Path]], retries: Retries, stage3_done: threading.Event,
                  jobs: int) -> Totals:
    """Stage 2: the short sim-time rostests one at a time until ``stage3_done``, then ``jobs`` workers take
    the rest, the long ones (longest ``time-limit`` first) only after stage 3 too."""
    short = [t for t in tests if not is_long(t[1])]
    long_ones = sorted((t for t in tests if is_long(t[1])), key=lambda t: -time_limit(t[1]))
    lock, total = threading.Lock(), Totals()

    def take() -> tuple[str, Path] | None:
        while True:
            with lock:
                if stage3_done.is_set() and long_ones:
                    return long_ones.pop(0)
                if short:
                    return short.pop(0)
                if not long_ones:
                    return None
            stage3_done.wait()

    def worker(first: bool) -> None:
        if not first:
            stage3_done.wait()
        while (item := take()) is not None:
            t = retries.first(*item)
            with lock:
                total.add(t)

    threads = [threading.Thread(target=worker, args=(i == 0,), daemon=True) for i in range(jobs)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    return total


def is_long(test: Path) -> bool:
    """A rostest that declares more time than the runner's default timeout (run after stage 3, one at a time)."""
    return time_limit(test) > ROSTEST_TIMEOUT_S


def rostest_retries() -> int:
    """CHEFBOT_TEST_RETRIES (more runs of a failed rostest file), default 1; a bad value is said and ignored."""
    raw = os.environ.get("CHEFBOT_TEST_RETRIES", "").strip()
    try:
        n = int(raw) if raw else RETRIES_DEFAULT
    except ValueError:
        n = -1
    if n < 0:
        log(f"CHEFBOT_TEST_RETRIES={raw!r} is not a whole number >= 0: using {RETRIES_DEFAULT}")
        n = RETRIES_DEFAULT
    return n


class Retries:
    """The rostest files that failed their first run, run again at the end (``first``, then ``finish``)."""

    def __init__(self, env: dict, runs: int) -> None:
        self.env = env
        self.runs = runs
        self.lock = threading.Lock()
        self.failed: list[tuple[str, Path, Totals]] = []     # (pkg, file, the first run's totals)
        self.notes: list[str] = []                           # RETRIED lines

    def first(self, pkg: str, test: Path) -> Totals:
        """The file's first run: its totals, or (when it failed and runs are left) none yet."""
        t = run_rostest(self.env, pkg, test)
        if t.failed and self.runs > 0:
            log(f"rostest {pkg}/{test.stem} failed; it runs again at the end")
            with self.lock:
                self.failed.append((pkg, test, t))
            return Totals()
        return t

    def finish(self) -> Totals:
        """Each failed file again, one at a time (up to ``runs`` more times); only its last run counts."""
        total = Totals()
        if self.failed:
            log(f"{len(self.failed)} failed rostest file(s) again, one at a time")
        for pkg, test, first in self.failed:
            for attempt in range(1, self.runs + 1):
                t = run_rostest(self.env, pkg, test, attempt + 1)
                if not t.failed:
                    break
            reasons = "; ".join(first.failures) or "failed"
            verdict = "passed" if not t.failed else "failed again"
            self.notes.append(f"RETRIED {pkg}/{test.stem}: {verdict} on run {attempt + 1}; the first run: {reasons}")
            total.add(t)
        return total


def run_rostest(env: dict, pkg: str, test: Path, run: int = 1) -> Totals:
    """One rostest file; its result line, figures and (when it failed) its log's tail printed as one block."""
    rel = test.relative_to(ROOT)
    name = f"{pkg}/{test.stem}"
    stem = f"{pkg}-{test.stem}" + (f"-run{run}" if run > 1 else "")     # a second run keeps the first's record
    out_dir = RESULTS / "rostest" / stem
    shutil.rmtree(out_dir, ignore_errors=True)
    logf = RESULTS / "rostest" / f"{stem}.log"
    t0 = time.monotonic()
    # An absolute path alone: rostest infers the package from it (pkg + path is rejected).
    # Its own results directory per test, since rostest picks the file names itself.
    cmd = ["rostest", "--results-base-dir", str(out_dir), str(test)]
    # Its own empty temporary directory, as TMPDIR: a test writes there (tempfile, $(optenv TMPDIR /tmp) in
    # a launch file), never into HOME or the source tree.
    tmp = RESULTS / "tmp" / stem
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    timeout = wall_timeout(test)
    rc, to = run_group(cmd, dict(env, TMPDIR=str(tmp)), timeout, logf)
    # rosunit-*.xml: one per test node, with its individual cases; rostest-*.xml: one
    # case per test node (fails when a node never wrote results).
    t = Totals()
    for xml in sorted(out_dir.glob("**/rosunit-*.xml")):
        t.add(junit_totals(xml, name))
    agg = Totals()
    for xml in sorted(out_dir.glob("**/rostest-*.xml")):
        agg.add(junit_totals(xml, name))
    if agg.failed and not t.failed:
        t.add(Totals(failed=agg.failed, failures=agg.failures))
    if to:
        t.failed += 1
        t.failures.append(f"{name}: timed out after {timeout:.0f} s")
    elif rc != 0 and not t.failed:
        t.failed += 1
        t.failures.append(f"{name}: rostest exit {rc}")
    if t.passed + t.failed == 0:
        t.failed += 1
        t.failures.append(f"{name}: no test result")
    again = f", run {run}" if run > 1 else ""
    block = [f"[test] rostest {rel}: {t.passed} passed, {t.failed} failed ({time.monotonic() - t0:.1f} s{again})"]
    if measured := figures(out_dir):
        block.append(measured)
    if t.failed:
        block.append(tail(logf))
    show("\n".join(block))
    return t


# ----------------------------------------------------------------- leak check
def leaked(token: str) -> list[tuple[int, str]]:
    me = os.getpid()
    out = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) == me:
            continue
        try:
            environ = (proc / "environ").read_bytes()
            if f"CHEFBOT_TEST_RUN={token}".encode() not in environ.split(b"\0"):
                continue
            cmdline = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        out.append((int(proc.name), cmdline.strip()))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", choices=["unit", "firmware", "rostest"], action="append")
    ap.add_argument("-k", dest="pattern", help="select tests (pytest -k; substring of the .test path)")
    args = ap.parse_args()
    only = set(args.only or ["unit", "firmware", "rostest"])

    RESULTS.mkdir(parents=True, exist_ok=True)
    token = uuid.uuid4().hex
    env = dict(os.environ, CHEFBOT_TEST_RUN=token, PYTHONDONTWRITEBYTECODE="1",
               ROS_HOME=str(RESULTS / "ros_home"), ROS_LOG_DIR=str(RESULTS / "ros_log"))
    env.pop("ROS_MASTER_URI", None)  # every runner brings its own master

    t0 = time.monotonic()
    total = Totals()
    timed, untimed = select_rostests(args.pattern) if "rostest" in only else ([], [])
    retries = Retries(env, rostest_retries())
    firmware = "firmware" in only and not args.pattern
    dirs = sorted_unit_dirs("unit" in only)
    background, unit_futures = None, []
    if (dirs or firmware) and timed:
        # stage 3 beside stages 1 and 2: the firmware, then one pytest directory at a time, at the
        # lowest priority
        log(f"stage 3: {'firmware + ' if firmware else ''}{len(dirs)} pytest director"
            f"{'y' if len(dirs) == 1 else 'ies'} one at a time at nice {UNIT_NICE}, beside stages 1 and 2")
        background = ThreadPoolExecutor(max_workers=1)
        unit_futures = [background.submit(run_firmware, env, UNIT_NICE)] if firmware else []
        unit_futures += [background.submit(pytest_dir, env, d, args.pattern, UNIT_NICE) for d in dirs]
        dirs, firmware = [], False
    stage3_done = threading.Event()
    if unit_futures:
        remaining = [len(unit_futures)]
        count_lock = threading.Lock()

        def one_done(_fut) -> None:
            with count_lock:
                remaining[0] -= 1
                if remaining[0] == 0:
                    log(f"stage 3 is done: sim-time rostests now {sim_jobs()} at a time")
                    stage3_done.set()

        for fut in unit_futures:
            fut.add_done_callback(one_done)
    else:
        stage3_done.set()
    try:
        total.add(run_side_stage(env, firmware, untimed, dirs, args.pattern, retries))
        if timed:
            n_long = sum(1 for t in timed if is_long(t[1]))
            log(f"stage 2: {len(timed)} rostest(s) in sim time ({n_long} long), one at a time beside stage 3, "
                f"then {sim_jobs()} at a time")
        total.add(run_sim_stage(timed, retries, stage3_done, sim_jobs()))
        for fut in unit_futures:
            total.add(fut.result())
        total.add(retries.finish())
    except BaseException:
        abandon(background)
        raise
    if background is not None:
        background.shutdown()

    time.sleep(0.5)
    strays = leaked(token)
    if strays:
        total.failed += 1
        total.failures.append(f"{len(strays)} process(es) outlived their test")
        for pid, cmd in strays:
            log(f"LEAK pid {pid}: {cmd[:160]}")
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    log(f"finished in {time.monotonic() - t0:.0f} s; results in {RESULTS.relative_to(ROOT)}")
    for note in retries.notes:
        log(note)
    for f in total.failures:
        log(f"FAILED {f}")
    line = f"{total.passed} passed, {total.failed} failed"
    if total.skipped:
        line += f", {total.skipped} skipped"
    print(line, flush=True)
    return 1 if total.failed or total.passed == 0 else 0


if __name__ == "__main__":
    stop_on_sigterm()
    sys.exit(main())
