"""ROS side of the robot monitor: ``/rosout_agg``, the master's topic list, ticked topics, one image topic.

Thin and thread-safe: rospy callbacks and the topic-list thread only store
what arrived (a bounded log queue, per-topic statistics and the last raw
message, the latest converted image); the window's timer collects it in the
GUI thread.  Nothing here is called from a callback into Qt, and nothing the
GUI thread calls blocks (the master is asked from a thread of its own).

Topics are subscribed as ``rospy.AnyMsg`` (raw bytes: rate and bandwidth for
any type, even one whose package is not installed here), and decoded on demand
with the class ``roslib.message.get_message_class`` finds, as rqt_topic does.
"""
from __future__ import annotations

import math
import threading
import time
import xmlrpc.client
from collections import deque
from dataclasses import dataclass, fields
from io import BytesIO

import rosgraph
import roslib.message
import rospy
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import Image

from chefbot_gui.app import master_proxy
from chefbot_gui.image_convert import IMAGE_TYPE, ImageError, ImageFrame, to_display
from chefbot_gui.log_buffer import DEFAULT_CAPACITY, LogEntry
from chefbot_gui.msg_tree import DecodeError
from chefbot_gui.topic_stats import DEFAULT_WINDOW_S, Stats, WindowStats


@dataclass(frozen=True)
class MonitorParams:
    """``rosout_topic``: aggregated log topic; ``list_period_s``: s between topic-list
    refreshes; ``window_s``: s of the rate/bandwidth window; ``log_capacity``: lines kept;
    ``master_timeout_s``: s one topic-list request may take."""

    rosout_topic: str = "/rosout_agg"
    list_period_s: float = 2.0
    window_s: float = DEFAULT_WINDOW_S
    log_capacity: int = DEFAULT_CAPACITY  # [lines] Console lines kept; the oldest are dropped (>= 1)
    master_timeout_s: float = 2.0

    def __post_init__(self) -> None:
        if not self.rosout_topic.strip():
            raise ValueError(f"rosout_topic must be a topic name, got {self.rosout_topic!r}")
        for name in ("list_period_s", "window_s", "master_timeout_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number of seconds > 0, got {v!r}")
        if self.log_capacity < 1:
            raise ValueError(f"log_capacity must be >= 1 line, got {self.log_capacity}")

    @classmethod
    def param_names(cls) -> dict[str, str]:
        """Field → private ROS parameter (``~window_s`` …), for ``chefbot_common.params.read_config``."""
        return {f.name: "~" + f.name for f in fields(cls)}


def log_entry(msg: Log) -> LogEntry:
    """A ``rosgraph_msgs/Log`` as the Console's entry (stamp in s)."""
    return LogEntry(stamp=msg.header.stamp.to_sec(), level=int(msg.level), node=msg.name, message=msg.msg,
                    file=msg.file, function=msg.function, line=int(msg.line))


def _raw_and_message(msg: object) -> tuple[bytes, object | None]:
    """(serialised bytes, decoded message or None) of what a subscriber callback got.

    rospy shares one subscription per topic and process: if this process already
    subscribed the topic with a real type (the delivery GUI does, for ``map`` and
    ``diagnostics``), our AnyMsg callback receives decoded messages instead of bytes.
    """
    buff = getattr(msg, "_buff", None)
    if buff is not None:
        return bytes(buff), None
    out = BytesIO()
    msg.serialize(out)
    return out.getvalue(), msg


class _Watched:
    """One ticked topic: its subscriber, statistics and last message (guarded by ``lock``)."""

    def __init__(self, window_s: float) -> None:
        self.lock = threading.Lock()
        self.stats = WindowStats(window_s=window_s)
        self.raw: bytes | None = None
        self.decoded: object | None = None
        self.type = ""
        self.serial = 0
        self.sub: rospy.Subscriber | None = None


class MonitorBridge:
    """Collects logs, topic traffic and images for the monitor window (see the module doc).

    Call :meth:`start` once, :meth:`shutdown` at exit; everything else may be
    called from the GUI thread at any time.
    """

    def __init__(self, params: MonitorParams | None = None) -> None:
        self.p = params or MonitorParams()
        self._logs: deque[LogEntry] = deque(maxlen=self.p.log_capacity)
        self._log_overflow = 0
        self._rosout: rospy.Subscriber | None = None
        self._watched: dict[str, _Watched] = {}
        self._listing: list[tuple[str, str]] | None = None
        self._listing_error = "asking the master for topics…"
        self._listing_serial = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._image_sub: rospy.Subscriber | None = None
        self._image = ImageFrame()
        self._image_stats = WindowStats(window_s=self.p.window_s)

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Subscribe to the log topic and start asking the master for topics."""
        self._rosout = rospy.Subscriber(self.p.rosout_topic, Log, self._on_log, queue_size=1000)
        self._thread = threading.Thread(target=self._list_loop, name="robot_monitor_topics", daemon=True)
        self._thread.start()

    def shutdown(self) -> None:
        """Unsubscribe everything and stop the topic-list thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=self.p.master_timeout_s + 1.0)
            self._thread = None
        if self._rosout is not None:
            self._rosout.unregister()
            self._rosout = None
        for name in list(self._watched):
            self.unsubscribe(name)
        self.set_image_topic(None)

    # ------------------------------------------------------------------ console
    def _on_log(self, msg: Log) -> None:
        if len(self._logs) == self._logs.maxlen:
            self._log_overflow += 1
        self._logs.append(log_entry(msg))

    def log_connections(self) -> int:
        """Publishers of the log topic connected to us (rosout: 1 once the link is up)."""
        return self._rosout.get_num_connections() if self._rosout is not None else 0

    def drain_logs(self, limit: int = 5000) -> list[LogEntry]:
        """The log entries received since the last call (at most ``limit``; the rest wait)."""
        out = []
        while self._logs and len(out) < limit:
            out.append(self._logs.popleft())
        return out

    # ------------------------------------------------------------------ topic list
    def _list_loop(self) -> None:
        uri = rosgraph.get_master_uri()
        caller = rospy.get_name()
        while not self._stop.is_set() and not rospy.is_shutdown():
            try:
                master = master_proxy(uri, self.p.master_timeout_s)
                code, msg, val = master.getPublishedTopics(caller, "/")
                if code != 1:
                    raise RuntimeError(msg)
                listing, error = sorted((str(n), str(t)) for n, t in val), ""
            except (OSError, xmlrpc.client.Error, RuntimeError, ValueError, TypeError) as e:
                listing, error = None, f"cannot list topics from the master at {uri}: {e}"
            with self._lock:
                if listing is not None:
                    self._listing = listing
                self._listing_error = error
                self._listing_serial += 1
            self._stop.wait(self.p.list_period_s)

    def topics(self) -> tuple[int, list[tuple[str, str]] | None, str]:
        """(serial, the master's latest ``(name, type)`` list or None, error text or '')."""
        with self._lock:
            return self._listing_serial, self._listing, self._listing_error

    # ------------------------------------------------------------------ ticked topics
    def subscribe(self, name: str) -> None:
        """Start measuring ``name`` (any type) and keeping its last message."""
        if name in self._watched:
            return
        w = _Watched(self.p.window_s)
        self._watched[name] = w
        w.sub = rospy.Subscriber(name, rospy.AnyMsg, self._on_topic, callback_args=w, queue_size=100)

    def unsubscribe(self, name: str) -> None:
        """Stop measuring ``name``."""
        w = self._watched.pop(name, None)
        if w is not None and w.sub is not None:
            w.sub.unregister()

    def subscribed(self) -> list[str]:
        """The topics measured now."""
        return list(self._watched)

    @staticmethod
    def _on_topic(msg: object, w: _Watched) -> None:
        raw, decoded = _raw_and_message(msg)
        header = getattr(msg, "_connection_header", None) or {}
        with w.lock:
            w.stats.add(time.monotonic(), len(raw))
            w.raw, w.decoded = raw, decoded
            w.type = header.get("type", w.type) if decoded is None else decoded._type
            w.serial += 1

    def stats(self, name: str) -> Stats:
        """Rate/bandwidth of a subscribed topic now (empty if not subscribed)."""
        w = self._watched.get(name)
        if w is None:
            return Stats()
        with w.lock:
            return w.stats.snapshot(time.monotonic())

    def last_message(self, name: str, listed_type: str) -> tuple[int, object | None]:
        """(serial, the last message of ``name`` decoded) — (0, None) before the first one.

        Raises :class:`DecodeError` naming the topic and type when the type is not
        installed here or the bytes do not decode.
        """
        w = self._watched.get(name)
        if w is None:
            return 0, None
        with w.lock:
            serial, raw, decoded, typ = w.serial, w.raw, w.decoded, w.type or listed_type
        if raw is None:
            return 0, None
        if decoded is not None:
            return serial, decoded
        cls = roslib.message.get_message_class(typ) if typ and typ != "*" else None
        if cls is None:
            raise DecodeError(f"{name}: message type {typ!r} is not installed here; "
                              f"rate and bandwidth only")
        try:
            msg = cls()
            msg.deserialize(raw)
        except Exception as e:  # genpy raises DeserializationError, struct.error, UnicodeError, …
            raise DecodeError(f"{name}: cannot decode {len(raw)} B as {typ}: {e}") from e
        with w.lock:
            if w.serial == serial:
                w.decoded = msg  # decode each message once
        return serial, msg

    # ------------------------------------------------------------------ image view
    def set_image_topic(self, name: str | None) -> None:
        """Show ``name`` (a ``sensor_msgs/Image`` topic) in the image view; None stops it."""
        if self._image_sub is not None:
            self._image_sub.unregister()
            self._image_sub = None
        with self._lock:
            self._image_stats = WindowStats(window_s=self.p.window_s)
            self._image = ImageFrame(self._image.serial + 1, name or "", None,
                                     f"waiting for an image on {name}" if name else "no image topic selected")
        if name:
            # AnyMsg, decoded here: a typed subscriber would be shared with an AnyMsg one on the
            # same topic in this process (rospy keeps one subscription per topic)
            self._image_sub = rospy.Subscriber(name, rospy.AnyMsg, self._on_image, callback_args=name,
                                               queue_size=1, buff_size=2 ** 24)

    def _on_image(self, msg: object, name: str) -> None:
        raw, decoded = _raw_and_message(msg)
        image, error = None, ""
        try:
            sent_type = (getattr(msg, "_connection_header", None) or {}).get("type", IMAGE_TYPE)
            if decoded is None and sent_type != IMAGE_TYPE:
                raise ImageError(f"carries {sent_type}, not {IMAGE_TYPE}")
            if decoded is None:
                decoded = Image()
                decoded.deserialize(raw)
            if getattr(decoded, "_type", "") != IMAGE_TYPE:
                raise ImageError(f"carries {getattr(decoded, '_type', '?')}, not {IMAGE_TYPE}")
            m = decoded
            image = to_display(m.encoding, m.width, m.height, m.step, bytes(m.data), bool(m.is_bigendian))
        except ImageError as e:
            error = f"{name}: {e}"
        except Exception as e:  # noqa: BLE001 - corrupt bytes: genpy raises several types
            error = f"{name}: cannot decode as {IMAGE_TYPE}: {e}"
        with self._lock:
            if self._image.topic != name:
                return  # a late frame of the previous topic
            self._image_stats.add(time.monotonic(), len(raw))
            self._image = ImageFrame(self._image.serial + 1, name, image, error)

    def latest_image(self) -> ImageFrame:
        """The image view's latest frame (or error), with the topic's rate."""
        with self._lock:
            f = self._image
            return ImageFrame(f.serial, f.topic, f.image, f.error, self._image_stats.snapshot(time.monotonic()))
