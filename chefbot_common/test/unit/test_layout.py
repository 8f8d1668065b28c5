"""chefbot_common depends on no other chefbot package (every package may depend on it)."""
from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src" / "chefbot_common"


def test_imports_no_chefbot_package() -> None:
    bad = []
    for py in sorted(SRC.glob("*.py")):
        for node in ast.walk(ast.parse(py.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            bad += [f"{py.name}: {n}" for n in names
                    if n.startswith("chefbot_") and not n.startswith("chefbot_common")]
    assert not bad, f"chefbot_common must not import other chefbot packages: {bad}"
