"""The recorded hotel bag of the SLAM tests and benchmark, whole or its first seconds (test helper)."""
from __future__ import annotations

from pathlib import Path

HOTEL_BAG = Path(__file__).resolve().parent / "fixtures" / "hotel_route.bag"


def hotel_bag_head(out: Path, seconds: float) -> Path:
    """Write the first ``seconds`` of the recorded hotel bag to ``out``; returns ``out``."""
    import rosbag
    with rosbag.Bag(str(HOTEL_BAG)) as src, rosbag.Bag(str(out), "w") as dst:
        for topic, msg, t in src.read_messages():
            if t.to_sec() > seconds:
                break
            dst.write(topic, msg, t)
    return out
