"""Import first in a node whose imports are slow: a SIGINT during them (roslaunch stopping the
launch because a required node died, e.g. map_server on a corrupt map) exits with status 1 instead
of printing a KeyboardInterrupt traceback.  Call :func:`restore` before ``rospy.init_node`` so
rospy's own shutdown handling takes over.
"""
from __future__ import annotations

import signal
import sys

signal.signal(signal.SIGINT, lambda *_: sys.exit(1))


def restore() -> None:
    """Python's default SIGINT handler again (rospy.init_node installs its own on top)."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
