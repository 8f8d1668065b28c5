"""chefbot_common.heap: the C heap's free pages go back to the system; the trimming thread and its setting.

The release is measured in a child process (a fresh heap): eight threads fill their own malloc arenas
with numpy arrays and free all but every twentieth, as a node's callbacks do; the RSS is read before and
after one trim.
"""
from __future__ import annotations

import os
import subprocess
import sys
import threading

import pytest

from chefbot_common import heap

FRAGMENT = """
import threading
import numpy as np
from chefbot_common import heap

def rss_mb():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024

keep = []
def work():
    arrs = [np.ones(6000) for _ in range(200)]      # 48 KB each: from the thread's arena, below mmap's threshold
    keep.extend(arrs[::20])                          # a few stay alive, so no arena can shrink from its top
threads = [threading.Thread(target=work) for _ in range(8)]
for t in threads: t.start()
for t in threads: t.join()
before = rss_mb()
released = heap.trim() if {trim} else False
print(before, rss_mb(), released)
"""


def fragmented(trim: bool) -> tuple[float, float, bool]:
    out = subprocess.run([sys.executable, "-c", FRAGMENT.replace("{trim}", str(trim))], capture_output=True,
                         text=True, timeout=120, check=True).stdout.split()
    return float(out[0]), float(out[1]), out[2] == "True"


@pytest.mark.skipif(heap._trim_function() is None, reason="the C library has no malloc_trim (not glibc)")
def test_trim_gives_the_free_pages_of_every_threads_arena_back() -> None:
    # 8 x 200 x 48 KB = 75 MB allocated, 95 % of it freed: without a trim the process keeps it all
    before, after, released = fragmented(trim=False)
    assert not released and after > before - 5.0, (before, after)
    before, after, released = fragmented(trim=True)
    assert released
    assert before - after > 40.0, (before, after)


@pytest.mark.parametrize(("raw", "seconds"), [(None, 30.0), ("", 30.0), (" 12.5 ", 12.5), ("0", 0.0), ("-3", 0.0)])
def test_period_from_the_environment(raw: str | None, seconds: float) -> None:
    assert heap.period(raw) == pytest.approx(seconds)


@pytest.mark.parametrize("raw", ["often", "nan", "inf"])
def test_a_bad_period_names_the_variable(raw: str) -> None:
    with pytest.raises(ValueError, match="CHEFBOT_HEAP_TRIM_S"):
        heap.period(raw)


def test_the_thread_trims_every_period_and_none_starts_when_off(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = threading.Semaphore(0)
    monkeypatch.setattr(heap, "trim", lambda: calls.release() or True)
    monkeypatch.setenv(heap.ENV, "0")
    assert heap.start_trimming() is None
    if heap._trim_function() is None:
        pytest.skip("the C library has no malloc_trim (not glibc)")
    th = heap.start_trimming(0.01)
    try:
        assert th is not None and th.daemon
        assert all(calls.acquire(timeout=10.0) for _ in range(3))      # it goes on trimming
    finally:
        th.stop.set()
        th.join(timeout=10.0)
    assert not th.is_alive()


def test_a_node_run_starts_trimming_and_survives_a_bad_setting() -> None:
    body = ("from chefbot_common import quiet_interrupt\nimport threading\n"
            "def main():\n    print(sorted(t.name for t in threading.enumerate() if t.name == 'heap trim'))\n"
            "    return 0\nquiet_interrupt.run(main)\n")
    for env, line in (({}, "['heap trim']"), ({heap.ENV: "0"}, "[]"), ({heap.ENV: "soon"}, "['heap trim']")):
        proc = subprocess.run([sys.executable, "-c", body], capture_output=True, text=True, timeout=60,
                              env={**{k: v for k, v in os.environ.items() if k != heap.ENV}, **env})
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout.strip() == line, (env, proc.stdout)
        if env.get(heap.ENV) == "soon":
            assert "CHEFBOT_HEAP_TRIM_S must be a number" in proc.stderr
