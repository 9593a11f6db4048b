import copy
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "configs" / "design" / "example.toml"


@pytest.fixture
def example_raw():
    """The example design as a raw config dict (a fresh copy per test)."""
    with open(EXAMPLE, "rb") as fh:
        return copy.deepcopy(tomllib.load(fh))
