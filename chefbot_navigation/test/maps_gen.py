"""Synthetic test maps (pure numpy): a generated office floor for benchmarks and tests."""
from __future__ import annotations

import numpy as np

from chefbot_common.grid import GridInfo, OccupancyMap


def office_map(size: int = 1200, resolution: float = 0.05, room: float = 6.0, door: float = 1.0,
               wall: float = 0.15, clutter: int = 300, seed: int = 0) -> OccupancyMap:
    """A square office floor (``size`` x ``size`` cells): a grid of rooms of ``room`` m with a door of
    ``door`` m in every wall segment and ``clutter`` random boxes (furniture), walled outside.

    Deterministic for a given seed.  Values: 0 free, 100 occupied.
    """
    rng = np.random.default_rng(seed)
    data = np.zeros((size, size), dtype=np.int8)
    rc, wc, dc = int(round(room / resolution)), max(int(round(wall / resolution)), 1), int(round(door / resolution))
    for k in range(0, size, rc):
        data[k:k + wc, :] = 100
        data[:, k:k + wc] = 100
    data[-wc:, :] = 100
    data[:, -wc:] = 100
    # a door in every wall segment between two rooms, at a random place along it
    n = size // rc + 1
    for i in range(n):
        for j in range(n):
            for horizontal in (True, False):
                lo = j * rc + wc + 2
                hi = min((j + 1) * rc - dc - 2, size - wc - dc - 2)
                if hi <= lo:
                    continue
                pos = int(rng.integers(lo, hi))
                k = i * rc
                if k <= 0 or k >= size - wc:
                    continue
                if horizontal:
                    data[k:k + wc, pos:pos + dc] = 0
                else:
                    data[pos:pos + dc, k:k + wc] = 0
    # furniture: boxes 0.4..1.2 m, kept off the doors by leaving 1 m around walls free of boxes
    for _ in range(clutter):
        bw, bh = (rng.uniform(0.4, 1.2, 2) / resolution).astype(int)
        r, c = rng.integers(0, size - max(bw, bh), 2)
        local_r, local_c = r % rc, c % rc
        margin = int(1.0 / resolution)
        if local_r < margin or local_c < margin or local_r + bh > rc - margin or local_c + bw > rc - margin:
            continue
        data[r:r + bh, c:c + bw] = 100
    return OccupancyMap(GridInfo(resolution, size, size, 0.0, 0.0, 0.0), data)
