"""Command line of ``deliver`` (pure): which tables, from which tables file, with clear errors."""
from __future__ import annotations

import argparse
from pathlib import Path

from chefbot_common.geometry import Pose2D
from chefbot_common.tables import TablesError, load_tables

DEFAULT_TABLES = Path(__file__).resolve().parents[2] / "maps" / "hotel_tables.yaml"   # of maps/hotel_map.yaml


class DeliverError(ValueError):
    """Bad command line or tables file; the message says what to fix."""


def parser() -> argparse.ArgumentParser:
    """Command-line parser of the ``deliver`` tool."""
    ap = argparse.ArgumentParser(
        prog="deliver", description="Send the robot to named tables in order (move_base action), printing the "
        "navigation state; exit 0 when every one was reached.")
    ap.add_argument("tables", nargs="+", metavar="TABLE", help="names from the tables file (e.g. table_1 home)")
    ap.add_argument("--tables", dest="tables_file", default=None,
                    help=f"tables YAML (default: param ~tables, else {DEFAULT_TABLES.name} of chefbot_navigation)")
    ap.add_argument("--timeout", type=float, default=600.0, help="s (ROS time) per table before cancelling")
    ap.add_argument("--keep-going", action="store_true", help="continue with the next table after a failure")
    return ap


def targets(names: list[str], tables_file: str | Path) -> list[tuple[str, Pose2D]]:
    """(name, pose) for every requested name, in order; DeliverError names an unknown one."""
    try:
        tables = load_tables(tables_file)
    except (TablesError, OSError) as exc:
        raise DeliverError(str(exc)) from None
    unknown = [n for n in names if n not in tables]
    if unknown:
        raise DeliverError(f"unknown table(s) {', '.join(unknown)} in {tables_file}; known: "
                           f"{', '.join(sorted(tables))}")
    return [(n, tables[n]) for n in names]
