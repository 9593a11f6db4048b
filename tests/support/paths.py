"""Where the tests find the repository's configs and their own data (tests never read ../shared)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
DATA = ROOT / "tests" / "data"
EXAMPLE = CONFIGS / "design" / "example.toml"
SIM_TANK = CONFIGS / "rigs" / "sim-tank.toml"
