"""The order queue's memory: every order and its history in an SQLite file (pure; stdlib ``sqlite3``).

A restarted dispatcher reads back the same queue: every order with its tables, priority, robot,
state and the robot it is assigned to, and each order's history of states.  Every change is one
transaction, committed before the call returns, so a dispatcher killed at any moment loses nothing
it has reported.  States and the moves allowed between them (:data:`MOVES`)::

    queued -> assigned -> loading -> on_the_way -> served
       ^         |           |            |
       +---------+-----------+------------+   (re-planned: its robot failed, was paused, or the plan changed)
    any state but served -> cancelled (staff) or failed (with a reason)

``served``, ``cancelled`` and ``failed`` are final: an order is never served twice, and one that
reached a final state never comes back.

Bad files give a :class:`StoreError` that names the file and what to do, never an empty queue: a
file that is not an SQLite database or fails SQLite's integrity check ("corrupt"), a database
without our tables or of another schema version, a database another process keeps locked longer
than ``timeout``.
"""
from __future__ import annotations

import json
import math
import sqlite3
from dataclasses import dataclass
from pathlib import Path

SCHEMA_VERSION = 1
STATES = ("queued", "assigned", "loading", "on_the_way", "served", "cancelled", "failed")
FINAL = ("served", "cancelled", "failed")
MOVES: dict[str, tuple[str, ...]] = {
    "queued": ("assigned", "cancelled", "failed"),
    "assigned": ("loading", "queued", "cancelled", "failed"),
    "loading": ("on_the_way", "queued", "cancelled", "failed"),
    "on_the_way": ("served", "queued", "cancelled", "failed"),
    "served": (), "cancelled": (), "failed": (),
}
_SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE orders (
    id TEXT PRIMARY KEY, tables TEXT NOT NULL, priority REAL NOT NULL, robot TEXT NOT NULL,
    created REAL NOT NULL, state TEXT NOT NULL, assigned TEXT NOT NULL, reason TEXT NOT NULL,
    updated REAL NOT NULL, seq INTEGER NOT NULL);
CREATE TABLE events (
    order_id TEXT NOT NULL REFERENCES orders(id), t REAL NOT NULL, state TEXT NOT NULL,
    robot TEXT NOT NULL, reason TEXT NOT NULL);
CREATE INDEX events_order ON events(order_id);
"""


class StoreError(RuntimeError):
    """The order database cannot be used (the message names the file, the cause and what to do)."""


class TransitionError(ValueError):
    """A state change the order's current state does not allow (names the order and both states)."""


@dataclass(frozen=True)
class StoredOrder:
    """One order as stored: what was asked for, where it is now."""

    id: str
    tables: tuple[str, ...]
    priority: float
    robot: str              # the robot asked for ("" = any)
    created: float
    state: str
    assigned: str           # the robot serving it now ("" = none)
    reason: str             # why it failed, was cancelled or re-planned ("" = nothing to say)
    updated: float


@dataclass(frozen=True)
class Event:
    """One entry of an order's history."""

    t: float
    state: str
    robot: str
    reason: str


class OrderStore:
    """The orders in the SQLite file ``path`` (created with its parent directories if missing).
    ``timeout`` (s): how long to wait for another process's lock before :class:`StoreError`.  Any
    thread may call it, one at a time (the caller holds a lock)."""

    def __init__(self, path: str | Path, timeout: float = 2.0) -> None:
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(f"order database {self.path}: cannot create its directory: {exc}") from exc
        try:
            # any thread may use it (the dispatcher node's callbacks), one at a time: the caller serialises
            self._db = sqlite3.connect(str(self.path), timeout=timeout, isolation_level=None, check_same_thread=False)
        except sqlite3.Error as exc:
            raise StoreError(f"order database {self.path}: cannot open it: {exc}") from exc
        try:
            self._open()
        except BaseException:
            self._db.close()
            raise

    def _open(self) -> None:
        db = self._db
        try:
            db.execute("PRAGMA foreign_keys = ON")
            tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
            if not tables:
                with self._write():      # one statement at a time: executescript would commit early
                    for statement in filter(str.strip, _SCHEMA.split(";")):
                        db.execute(statement)
                    db.execute("INSERT INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),))
                return
            check = db.execute("PRAGMA quick_check").fetchone()[0]
        except sqlite3.DatabaseError as exc:
            raise self._explain(exc) from exc
        if check != "ok":
            raise StoreError(f"order database {self.path} is corrupt (SQLite: {check}); move it aside to start "
                             "an empty queue, or restore a backup")
        if not {"meta", "orders", "events"} <= tables:
            raise StoreError(f"{self.path} is an SQLite database but not a ChefBot order database (tables "
                             f"{sorted(tables)}); give the dispatcher another path")
        row = db.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()
        if row is None or row[0] != str(SCHEMA_VERSION):
            raise StoreError(f"order database {self.path} has schema version {row[0] if row else 'none'}, this "
                             f"dispatcher reads version {SCHEMA_VERSION}")

    def _explain(self, exc: sqlite3.Error) -> StoreError:
        text = str(exc)
        if "locked" in text or "busy" in text:
            return StoreError(f"order database {self.path} is locked by another process ({text}); is another "
                              "dispatcher running on it?")
        if "not a database" in text or "malformed" in text or "corrupt" in text:
            return StoreError(f"order database {self.path} is corrupt ({text}); move it aside to start an "
                              "empty queue, or restore a backup")
        return StoreError(f"order database {self.path}: {text}")

    def _write(self):
        """A transaction that takes the write lock at once (BEGIN IMMEDIATE), committed on success."""
        store = self

        class _Tx:
            def __enter__(self) -> sqlite3.Connection:
                try:
                    store._db.execute("BEGIN IMMEDIATE")
                except sqlite3.Error as exc:
                    raise store._explain(exc) from exc
                return store._db

            def __exit__(self, kind, value, tb) -> bool:
                try:
                    store._db.execute("COMMIT" if kind is None else "ROLLBACK")
                except sqlite3.Error as exc:
                    if kind is None:
                        raise store._explain(exc) from exc
                if isinstance(value, sqlite3.Error) and not isinstance(value, sqlite3.IntegrityError):
                    raise store._explain(value) from value
                return False
        return _Tx()

    def close(self) -> None:
        """Close the file (every change is already committed)."""
        self._db.close()

    # ------------------------------------------------------------------ orders
    def add(self, tables: tuple[str, ...] | list[str], created: float, priority: float = 1.0, robot: str = "",
            order_id: str | None = None) -> StoredOrder:
        """A new order, ``queued``; its id is ``order_id`` or the next free ``o<n>``.  ValueError for a bad
        order (no table, priority < 1, a time that is not finite, an id already used)."""
        tables = tuple(tables)
        if not tables or any(not isinstance(t, str) or not t for t in tables):
            raise ValueError(f"an order needs at least one table name, got {list(tables)}")
        if not (math.isfinite(priority) and priority >= 1.0):
            raise ValueError(f"priority must be a number >= 1, got {priority}")
        if not math.isfinite(created):
            raise ValueError(f"created must be a finite time, got {created}")
        with self._write() as db:
            seq = db.execute("SELECT COALESCE(MAX(seq), 0) + 1 FROM orders").fetchone()[0]
            oid = order_id or f"o{seq}"
            if db.execute("SELECT 1 FROM orders WHERE id = ?", (oid,)).fetchone():
                raise ValueError(f"order id {oid} is already used")
            db.execute("INSERT INTO orders VALUES (?, ?, ?, ?, ?, 'queued', '', '', ?, ?)",
                       (oid, json.dumps(tables), float(priority), robot, float(created), float(created), seq))
            db.execute("INSERT INTO events VALUES (?, ?, 'queued', ?, '')", (oid, float(created), robot))
        return self.get(oid)

    def move(self, order_id: str, state: str, t: float, robot: str = "", reason: str = "") -> StoredOrder:
        """Move an order to ``state`` at ``t`` (``robot``: the one serving it; ``reason``: why).
        TransitionError if its state does not allow it, KeyError for an unknown order."""
        if state not in STATES:
            raise ValueError(f"unknown order state {state!r}; one of {', '.join(STATES)}")
        with self._write() as db:
            row = db.execute("SELECT state, assigned FROM orders WHERE id = ?", (order_id,)).fetchone()
            if row is None:
                raise KeyError(f"no order {order_id}")
            now, assigned = row
            if state not in MOVES[now]:
                raise TransitionError(f"order {order_id} is {now}: it cannot become {state}")
            keep = robot or (assigned if state in ("loading", "on_the_way", "served") else "")
            db.execute("UPDATE orders SET state = ?, assigned = ?, reason = ?, updated = ? WHERE id = ?",
                       (state, keep, reason, float(t), order_id))
            db.execute("INSERT INTO events VALUES (?, ?, ?, ?, ?)", (order_id, float(t), state, keep, reason))
        return self.get(order_id)

    def get(self, order_id: str) -> StoredOrder:
        """The order ``order_id`` (KeyError if there is none)."""
        row = self._query("SELECT * FROM orders WHERE id = ?", (order_id,))
        if not row:
            raise KeyError(f"no order {order_id}")
        return _order(row[0])

    def orders(self, open_only: bool = False) -> list[StoredOrder]:
        """Every order (``open_only``: those not in a final state), oldest first."""
        where = f" WHERE state NOT IN ({','.join('?' * len(FINAL))})" if open_only else ""
        return [_order(r) for r in self._query(f"SELECT * FROM orders{where} ORDER BY seq", FINAL if open_only else ())]

    def latest(self, n: int, final_only: bool = False) -> list[StoredOrder]:
        """The ``n`` newest orders (``final_only``: of those served, cancelled or failed), oldest first."""
        where = f" WHERE state IN ({','.join('?' * len(FINAL))})" if final_only else ""
        rows = self._query(f"SELECT * FROM orders{where} ORDER BY seq DESC LIMIT ?",
                           (*(FINAL if final_only else ()), int(n)))
        return [_order(r) for r in reversed(rows)]

    def history(self, order_id: str) -> list[Event]:
        """The order's states in the order they were taken."""
        self.get(order_id)
        return [Event(*r) for r in self._query(
            "SELECT t, state, robot, reason FROM events WHERE order_id = ? ORDER BY rowid", (order_id,))]

    def _query(self, sql: str, args: tuple = ()) -> list[tuple]:
        try:
            return self._db.execute(sql, args).fetchall()
        except sqlite3.Error as exc:
            raise self._explain(exc) from exc


def _order(row: tuple) -> StoredOrder:
    oid, tables, priority, robot, created, state, assigned, reason, updated, _ = row
    return StoredOrder(oid, tuple(json.loads(tables)), priority, robot, created, state, assigned, reason, updated)
