"""A validated design (`Design`): its values by section and key (numbers may be arrays), its wavelength grid and
its sensor profile. `uwlab.model.build` makes one from a config; `uwlab.model.evaluation` evaluates it."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from uwlab.model.grid import WavelengthGrid
from uwlab.model.sensor import SensorProfile


@dataclass(frozen=True, eq=False)
class Design:
    """A validated design: `values` is {section: {key: value}} (numbers may be arrays); categorical inputs
    (spectra, water, reflectance and transmittance files, sensor profile) are resolved to data."""

    values: dict = field(repr=False)
    grid: WavelengthGrid
    sensor: SensorProfile
    base_dir: Path | None = None

    def __getitem__(self, dotted: str):
        section, key = dotted.split(".")
        return self.values[section][key]

    def with_values(self, **dotted) -> Design:
        """A copy with some numeric values replaced, e.g. ``with_values(**{"lens.f_number": 4.0})``."""
        values: dict[str, Any] = {s: list(v) if isinstance(v, list) else dict(v) for s, v in self.values.items()}
        for name, value in dotted.items():
            section, key = name.split(".")
            values[section][key] = value
        return replace(self, values=values)
