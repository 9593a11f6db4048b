"""Water inherent optical properties: absorption a(λ), scattering b(λ), beam attenuation c = a + b [1/m].

Only directly transmitted light is modelled (Beer–Lambert along each path, exp(−c d)); light scattered into
the path is neglected, as in the paper. `attenuation_scale` multiplies c.

Sources (see configs/water/README.md for the files and how their gaps were filled):
- Jerlov types I, II, III, 1C, 3C, 5C, 7C, 9C: Solonenko & Mobley, "Inherent optical properties of Jerlov water
  types", Applied Optics 54(17), 5392–5401 (2015), tabulated 300–700 nm.
- ``jerlov-<type>-williamson2022`` (IB, II, III, 1C, 3C, 5C): the measured IOPs of Williamson & Hollins, Applied
  Optics 61, 9951–9961 (2022), 300–800 nm (configs/water/jerlov_williamson2022.csv), the same extension beyond.
- ``pure-fresh``: absorption of pure water from Pope & Fry, Applied Optics 36, 8710–8723 (1997), 380–727.5 nm,
  continued to the red by configs/water/pure_water_red_extension.csv; scattering of pure fresh water
  b_w(λ) = 0.0022 (λ / 500 nm)^−4.32 1/m (Morel, "Optical properties of pure water and pure sea water", in
  Optical Aspects of Oceanography, 1974).
- A CSV with columns ``wavelength_nm, a_per_m, b_per_m``.

Extension outside a table (convention):
- Tables are interpolated linearly in λ; below the first wavelength the first value is held.
- Jerlov types above their last wavelength λ_max (700 nm; Williamson & Hollins 800 nm):
  a(λ) = a_w(λ) + [a(λ_max) − a_w(λ_max)] (the non-water absorption held constant, pure water's steep red rise
  added), and b(λ) continued by the power law
  b ∝ λ^−n fitted (log–log least squares) to the type's tabulated b at 550–700 nm.
- Pure water above its last tabulated wavelength, and CSV water beyond either end: the end value is held.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.model.data import config_dir, csv_rows, read_csv_columns, sorted_unique
from uwlab.model.grid import WavelengthGrid

JERLOV_TYPES = ("I", "II", "III", "1C", "3C", "5C", "7C", "9C")
# The measured tables of Williamson & Hollins (2022) (configs/water/jerlov_williamson2022.csv), as an alternative
WILLIAMSON_TYPES = ("IB", "II", "III", "1C", "3C", "5C")
WILLIAMSON_SUFFIX = "-williamson2022"
TABLES = {"": "jerlov.csv", WILLIAMSON_SUFFIX: "jerlov_williamson2022.csv"}
WATER_TYPES = (
    tuple(f"jerlov-{t}" for t in JERLOV_TYPES)
    + tuple(f"jerlov-{t}{WILLIAMSON_SUFFIX}" for t in WILLIAMSON_TYPES)
    + ("pure-fresh",)
)
MOREL_B500_PER_M = 0.0022
MOREL_EXPONENT = 4.32


@dataclass(frozen=True)
class WaterIOP:
    """Absorption and scattering [1/m] on a wavelength grid."""

    a_per_m: np.ndarray
    b_per_m: np.ndarray

    @property
    def c_per_m(self) -> np.ndarray:
        return self.a_per_m + self.b_per_m


def pure_water_scattering(nm: np.ndarray) -> np.ndarray:
    """Morel (1974) pure fresh water scattering b_w(λ) = 0.0022 (λ/500)^−4.32 [1/m]."""
    return MOREL_B500_PER_M * (np.asarray(nm) / 500.0) ** -MOREL_EXPONENT


def scattering_parts(b_per_m: np.ndarray, nm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(b_w, b_p) [1/m]: a water's scattering b(λ) split into the molecular scattering of pure water,
    b_w = min(b, Morel's b_w(λ)), and the rest, b_p = b − b_w, attributed to suspended particles.

    The two parts scatter with different phase functions (`uwlab.model.scattering`): pure water back-scatters half
    of its light, Petzold's average particles 1.8 %; the veiling light of the extended model depends on the split.
    A Jerlov type's tabulated b is mostly particles' (Solonenko & Mobley 2015: type I b(550) = 0.0017 1/m ≈ b_w,
    coastal 1C 0.365 1/m ≫ b_w = 0.0015 1/m); pure fresh water is all molecular.

    >>> b_w, b_p = scattering_parts(np.array([0.0017, 0.365]), np.array([550.0, 550.0]))
    >>> np.round(b_w, 5).tolist(), np.round(b_p, 5).tolist()
    ([0.00146, 0.00146], [0.00024, 0.36354])
    """
    b = np.asarray(b_per_m, float)
    molecular = np.minimum(b, pure_water_scattering(nm))
    return molecular, b - molecular


@lru_cache(maxsize=4)
def _pure_water_table(root: Path) -> tuple[np.ndarray, np.ndarray]:
    base = read_csv_columns(root / "water" / "pure_water_pope_fry_1997.csv", ("wavelength_nm", "a_per_m"), "water.type")
    red = read_csv_columns(root / "water" / "pure_water_red_extension.csv", ("wavelength_nm", "a_per_m"), "water.type")
    beyond = red["wavelength_nm"] > base["wavelength_nm"][-1]
    nm = np.concatenate([base["wavelength_nm"], red["wavelength_nm"][beyond]])
    a = np.concatenate([base["a_per_m"], red["a_per_m"][beyond]])
    return nm, a


def pure_water_absorption(nm: np.ndarray) -> np.ndarray:
    """Pope & Fry (1997) absorption of pure water, continued to the red, end values held [1/m]."""
    table_nm, table_a = _pure_water_table(config_dir())
    return np.interp(nm, table_nm, table_a)


@lru_cache(maxsize=4)
def _jerlov_table(root: Path, name: str = "jerlov.csv") -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Water type → (wavelength_nm, a_per_m, b_per_m) of ``configs/water/<name>``, sorted by wavelength."""
    header, rows_read = csv_rows(root / "water" / name, "water.type")
    table = {column: [row[i] for _, row in rows_read] for i, column in enumerate(header)}
    lines = [number for number, _ in rows_read]
    types = np.array(table["water_type"])
    columns = [np.array(table[c], dtype=float) for c in ("wavelength_nm", "a_per_m", "b_per_m")]
    out = {}
    for water_type in dict.fromkeys(table["water_type"]):
        rows = np.flatnonzero(types == water_type)
        values = sorted_unique(
            np.column_stack([c[rows] for c in columns]),
            [lines[r] for r in rows],
            root / "water" / name,
            "water.type",
            ("wavelength_nm", "a_per_m", "b_per_m"),
        )
        out[water_type] = (values[:, 0], values[:, 1], values[:, 2])
    return out


def _power_law_exponent(nm: np.ndarray, b: np.ndarray) -> float:
    sel = (nm >= 550) & (nm <= 700)
    slope = np.polyfit(np.log(nm[sel]), np.log(b[sel]), 1)[0]
    return -float(slope)


def jerlov(water_type: str, grid: WavelengthGrid, table: str = "jerlov.csv") -> WaterIOP:
    """IOPs of a Jerlov type of `table` on the grid, extended to the red as the module docstring states."""
    nm, a, b = _jerlov_table(config_dir(), table)[water_type]
    out_a = np.interp(grid.nm, nm, a)
    out_b = np.interp(grid.nm, nm, b)
    red = grid.nm > nm[-1]
    if np.any(red):
        a_w = pure_water_absorption(np.append(grid.nm[red], nm[-1]))
        out_a[red] = a_w[:-1] + (a[-1] - a_w[-1])
        out_b[red] = b[-1] * (grid.nm[red] / nm[-1]) ** -_power_law_exponent(nm, b)
    return WaterIOP(out_a, out_b)


def pure_fresh(grid: WavelengthGrid) -> WaterIOP:
    return WaterIOP(pure_water_absorption(grid.nm), pure_water_scattering(grid.nm))


@lru_cache(maxsize=32)
def water_iop(spec: str, grid: WavelengthGrid, key: str = "water.type") -> WaterIOP:
    """A named water type (see WATER_TYPES) or a CSV path → IOPs on the grid."""
    if spec == "pure-fresh":
        return pure_fresh(grid)
    if spec.startswith("jerlov-") and spec[len("jerlov-") :] in JERLOV_TYPES:
        return jerlov(spec[len("jerlov-") :], grid)
    if spec.startswith("jerlov-") and spec.endswith(WILLIAMSON_SUFFIX):
        name = spec[len("jerlov-") : -len(WILLIAMSON_SUFFIX)]
        if name in WILLIAMSON_TYPES:
            return jerlov(name, grid, TABLES[WILLIAMSON_SUFFIX])
    path = Path(spec)
    if path.suffix.lower() != ".csv":
        raise ConfigError(key, spec, f"unknown water type; use one of {', '.join(WATER_TYPES)} or a .csv file")
    table = read_csv_columns(path, ("wavelength_nm", "a_per_m", "b_per_m"), key)
    if np.any(table["a_per_m"] < 0) or np.any(table["b_per_m"] < 0):
        raise ConfigError(key, spec, "negative a_per_m or b_per_m")
    return WaterIOP(
        np.interp(grid.nm, table["wavelength_nm"], table["a_per_m"]),
        np.interp(grid.nm, table["wavelength_nm"], table["b_per_m"]),
    )
