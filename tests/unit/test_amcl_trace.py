"""tools/amcl_trace.py --summary: which recorded diagnostics lines it reports."""
from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("chefbot_tools_amcl_trace", ROOT / "tools" / "amcl_trace.py")
amcl_trace = importlib.util.module_from_spec(spec)
sys.modules[spec.name] = amcl_trace
spec.loader.exec_module(amcl_trace)


def _rec(t: float, x: float, injected: int = 0, switches: int = 0) -> dict:
    return {"t": t, "level": 0, "msg": "localized", "x": str(x), "y": "2.0", "mean_beam_fit": "0.8",
            "w_slow": "1.0", "w_fast": "0.8", "injected_last_resample": str(injected),
            "estimate_switches": str(switches), "std_xy": "0.05", "gx": 1.0, "gy": 2.0}


def test_summary_reports_injection_switches_and_errors(tmp_path: Path) -> None:
    path = tmp_path / "trace.jsonl"
    records = [_rec(1.0, 1.01), _rec(2.0, 1.0, injected=120), _rec(3.0, 1.02, switches=1), _rec(4.0, 1.5, switches=1),
               {"t": 5.0, "level": 2, "msg": "no usable map yet"}]
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    lines = amcl_trace.summary(str(path))
    assert len(lines) == 3
    assert "injected  120" in lines[0]
    assert "switches   1" in lines[1]
    assert "error 0.500 m" in lines[2]


def test_truth_at_interpolates_at_the_estimates_stamp() -> None:
    history = [(1.0, 0.0, 2.0), (1.1, 0.035, 2.0), (1.2, 0.07, 2.0)]
    assert amcl_trace.truth_at(history, 1.15) == pytest.approx((0.0525, 2.0))
    assert amcl_trace.truth_at(history, 1.0) == (0.0, 2.0)
    assert amcl_trace.truth_at(history, 1.2) == (0.07, 2.0)
    assert amcl_trace.truth_at(history, 0.9) is None and amcl_trace.truth_at(history, 1.3) is None
    assert amcl_trace.truth_at([], 1.0) is None
