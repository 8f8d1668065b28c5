"""The order queue's SQLite store (chefbot_fleet.order_store): orders and histories survive a restart,
only allowed state changes, clear errors for corrupt, foreign, newer and locked databases."""
from __future__ import annotations

import sqlite3

import pytest

from chefbot_fleet.order_store import FINAL, MOVES, OrderStore, StoreError, TransitionError


def test_a_restarted_store_has_the_same_queue_and_histories(tmp_path) -> None:
    path = tmp_path / "ros" / "chefbot_orders.db"          # the directory is made
    store = OrderStore(path)
    a = store.add(["table_3", "table_7"], 10.0)
    b = store.add(["table_1"], 11.0, priority=2.0, robot="chefbot2")
    c = store.add(["table_9"], 12.0, order_id="walk-in")
    assert (a.id, b.id, c.id) == ("o1", "o2", "walk-in")
    store.move(a.id, "assigned", 13.0, robot="chefbot1")
    store.move(a.id, "loading", 20.0)
    store.move(b.id, "cancelled", 21.0, reason="guest left")
    store.close()                                            # the dispatcher dies here

    again = OrderStore(path)
    got = {o.id: o for o in again.orders()}
    assert got["o1"].tables == ("table_3", "table_7") and got["o1"].state == "loading"
    assert got["o1"].assigned == "chefbot1"                 # the robot is kept through loading
    assert got["o2"].priority == 2.0 and got["o2"].robot == "chefbot2" and got["o2"].reason == "guest left"
    assert [o.id for o in again.orders(open_only=True)] == ["o1", "walk-in"]
    assert [(e.state, e.robot) for e in again.history("o1")] == [("queued", ""), ("assigned", "chefbot1"),
                                                                  ("loading", "chefbot1")]
    assert again.add(["table_2"], 30.0).id == "o4"           # ids go on, never reused
    assert [o.id for o in again.latest(2)] == ["walk-in", "o4"]
    assert [o.id for o in again.latest(5, final_only=True)] == ["o2"]
    again.close()


def test_only_allowed_moves_and_final_states_are_final(tmp_path) -> None:
    store = OrderStore(tmp_path / "q.db")
    o = store.add(["table_1"], 0.0)
    with pytest.raises(TransitionError, match="o1 is queued: it cannot become served"):
        store.move(o.id, "served", 1.0)
    for state in ("assigned", "loading", "on_the_way", "served"):
        store.move(o.id, state, 2.0, robot="chefbot1" if state == "assigned" else "")
    for state in MOVES:                                      # served twice, or revived: never
        with pytest.raises(TransitionError):
            store.move(o.id, state, 3.0)
    assert all(MOVES[s] == () for s in FINAL)
    # a robot failing mid-trip: the order goes back to the queue, with the reason
    p = store.add(["table_2"], 0.0)
    store.move(p.id, "assigned", 1.0, robot="chefbot2")
    store.move(p.id, "loading", 2.0)
    store.move(p.id, "on_the_way", 3.0)
    back = store.move(p.id, "queued", 4.0, reason="chefbot2 stopped reporting")
    assert back.state == "queued" and back.assigned == "" and back.reason == "chefbot2 stopped reporting"
    with pytest.raises(KeyError):
        store.move("o99", "assigned", 1.0)
    with pytest.raises(ValueError, match="unknown order state"):
        store.move(p.id, "lost", 1.0)


def test_bad_orders_are_refused_and_nothing_is_stored(tmp_path) -> None:
    store = OrderStore(tmp_path / "q.db")
    for tables, kw, match in (([], {}, "at least one table"), (["table_1", ""], {}, "at least one table"),
                              (["table_1"], {"priority": 0.5}, "priority"),
                              (["table_1"], {"created": float("inf")}, "finite")):
        with pytest.raises(ValueError, match=match):
            store.add(tables, kw.pop("created", 0.0), **kw)
    store.add(["table_1"], 0.0, order_id="x")
    with pytest.raises(ValueError, match="already used"):
        store.add(["table_2"], 0.0, order_id="x")
    assert [o.id for o in store.orders()] == ["x"]


def test_a_corrupt_file_is_an_error_not_an_empty_queue(tmp_path) -> None:
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"this is not a database at all" * 200)
    with pytest.raises(StoreError, match=r"junk\.db is corrupt.*move it aside"):
        OrderStore(junk)
    # a real database, damaged inside: its pages overwritten
    path = tmp_path / "q.db"
    store = OrderStore(path)
    for k in range(200):
        store.add([f"table_{k % 9 + 1}"], float(k))
    store.close()
    data = bytearray(path.read_bytes())
    page = 4096
    data[page: 3 * page] = b"\xff" * (2 * page)
    path.write_bytes(bytes(data))
    with pytest.raises(StoreError, match="corrupt"):
        OrderStore(path).orders()


def test_a_foreign_or_newer_database_is_refused(tmp_path) -> None:
    other = tmp_path / "other.db"
    with sqlite3.connect(other) as db:
        db.execute("CREATE TABLE guests (name TEXT)")
    with pytest.raises(StoreError, match="not a ChefBot order database"):
        OrderStore(other)
    newer = tmp_path / "newer.db"
    OrderStore(newer).close()
    with sqlite3.connect(newer) as db:
        db.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
    with pytest.raises(StoreError, match="schema version 99"):
        OrderStore(newer)


def test_a_database_locked_by_another_process_is_reported(tmp_path) -> None:
    path = tmp_path / "q.db"
    OrderStore(path).close()
    holder = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
    holder.execute("BEGIN EXCLUSIVE")                       # another process holds it: not even readable
    try:
        with pytest.raises(StoreError, match="locked by another process"):
            OrderStore(path, timeout=0.2)
    finally:
        holder.execute("ROLLBACK")
    holder.execute("BEGIN IMMEDIATE")                       # another dispatcher in the middle of a write
    try:
        store = OrderStore(path, timeout=0.2)
        assert store.orders() == []                         # reading goes on
        with pytest.raises(StoreError, match="locked by another process"):
            store.add(["table_1"], 0.0)
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    # the lock gone, the same store works and the failed add left nothing behind
    assert store.add(["table_1"], 1.0).id == "o1"
    store.close()


def test_an_unwritable_place_is_a_clear_error(tmp_path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(StoreError, match="cannot create its directory"):
        OrderStore(blocker / "sub" / "q.db")
