"""chefbot_navigation's unit tests import the test-only helpers beside them (maps_gen, planner_reference)."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
