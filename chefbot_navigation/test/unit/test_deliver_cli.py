"""deliver's command line: names resolved from the tables file in order; clear errors."""
from __future__ import annotations

from pathlib import Path

import pytest

from chefbot_navigation.deliver_cli import DEFAULT_TABLES, DeliverError, parser, targets

CAFE = Path(__file__).resolve().parents[2] / "maps" / "cafe_tables.yaml"


def test_names_in_order_from_the_given_file() -> None:
    args = parser().parse_args(["table_s3", "home", "--tables", str(CAFE)])
    legs = targets(args.tables, args.tables_file)
    assert [n for n, _ in legs] == ["table_s3", "home"]
    assert legs[0][1].x == pytest.approx(4.75)
    assert DEFAULT_TABLES.is_file()


def test_unknown_table_and_missing_file_are_named(tmp_path: Path) -> None:
    with pytest.raises(DeliverError, match="unknown table.*table_99.*known: home"):
        targets(["table_99"], CAFE)
    with pytest.raises(DeliverError, match="nope.yaml"):
        targets(["home"], tmp_path / "nope.yaml")
    with pytest.raises(SystemExit):
        parser().parse_args([])
