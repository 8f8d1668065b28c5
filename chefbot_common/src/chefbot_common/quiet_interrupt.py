"""A node stopped while it starts exits quietly (status 1), not with a Python traceback.

roslaunch stops every node of a launch with SIGINT when a required node dies (e.g. map_server on a
corrupt map), which may be while a sibling node is still starting:

* during its imports: import this module first in a node whose imports are slow, and a SIGINT
  during them exits with status 1 instead of a ``KeyboardInterrupt`` traceback;
* inside ``rospy.init_node``, while the node registers with the master: rospy's handler marks the
  node shut down and ``init_node`` raises ``ROSInitException("init_node interrupted before it
  could complete")``.  End the node with :func:`run` (``run(main)`` instead of ``sys.exit(main())``)
  and that too exits with status 1 and no traceback;
* while the node's main thread waits for the master (``rospy.get_param``, registering a
  publisher): rospy's signal handler runs on that thread and unregisters the node through the same
  locked master proxy, which that thread holds, so the node deadlocks until roslaunch escalates to
  SIGKILL 17 s later (rospy's ``_LockedServerProxy``, ros_comm #461).  Under :func:`run`,
  rospy's shutdown then runs on a thread of its own, which waits for the call in progress.

Any other exception still prints its traceback: only a stop requested by a signal is quiet.
"""
from __future__ import annotations

# isort: off
import os
import signal

# first, before even this module's other imports; os._exit, not sys.exit: a SystemExit raised inside
# a C extension's module init (scipy's) becomes an "ImportError: initialization failed" traceback,
# and before init_node there is nothing to clean up
signal.signal(signal.SIGINT, lambda *_: os._exit(1))
# isort: on
import sys  # noqa: E402
import threading  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import NoReturn  # noqa: E402


def restore() -> None:
    """Python's default SIGINT handler again (rospy.init_node installs its own on top)."""
    signal.signal(signal.SIGINT, signal.default_int_handler)


def run(main: Callable[[], int | None]) -> NoReturn:
    """``sys.exit(main())``, but exit 1 quietly when a SIGINT stops the node before ``rospy.init_node``
    has installed rospy's handler (``KeyboardInterrupt``) or while it registers (``ROSInitException``
    once rospy is shut down).  Restores Python's SIGINT handler first, so rospy chains to it, and
    has rospy's signal handler hand the shutdown to a thread when the master proxy is busy.  Also
    starts :func:`chefbot_common.heap.start_trimming` (the C heap's free pages returned every 30 s)."""
    restore()
    from chefbot_common import heap
    try:
        heap.start_trimming()
    except ValueError as exc:       # a bad CHEFBOT_HEAP_TRIM_S: said, and the default used
        print(f"{exc}; using {heap.DEFAULT_PERIOD_S:g} s", file=sys.stderr, flush=True)
        heap.start_trimming(heap.DEFAULT_PERIOD_S)
    import rospy  # here: a node that ends with run() has imported it already; this module must not

    rospy.core._ros_signal = _deadlock_free(rospy.core._ros_signal, rospy.core)
    try:
        status = main()
    except KeyboardInterrupt:
        status = 1
    except rospy.ROSInitException:
        if not rospy.core.is_shutdown():
            raise
        status = 1
    sys.exit(status)


def _deadlock_free(ros_signal: Callable, core) -> Callable:
    """rospy's signal handler, run on a thread of its own when a thread (maybe the one the signal
    interrupted) is inside a call to the master or another node; otherwise inline as rospy does
    (so shutdown hooks that stop the motors run on the main thread, as always)."""
    def handler(sig: int, frame) -> None:
        proxies = list(core._xmlrpc_cache.values())    # rospy's cache of _LockedServerProxy
        if any(getattr(p, "_lock", None) is not None and p._lock.locked() for p in proxies):
            threading.Thread(target=ros_signal, args=(sig, None), name="rospy-signal-shutdown").start()
        else:
            ros_signal(sig, frame)
    return handler
