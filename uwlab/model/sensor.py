"""Image sensors: profiles and the EMVA 1288 linear camera model.

EMVA 1288 Release 4.0 (linear), §2: the mean number of electrons generated during the exposure is
μ_e = η μ_p with μ_p = A t_exp / (h c) ∫ E(λ) λ dλ photons per pixel; spectrally,
μ_e = (A t_exp / (h c)) ∫ E_s(λ) λ η(λ) dλ. The digital signal is μ_y = μ_y,dark + K μ_e, with system gain K
[DN/e⁻]; here K = K₀ · 10^(gain_dB/20) and both K₀ and μ_y,dark scale by 2^(bits − profile bits) at another
output bit depth. μ_e is clipped at the saturation capacity and μ_y at the full scale 2^bits − 1. Temporal noise
σ_y² = K² (σ_d² + μ_e) + σ_q², σ_q² = 1/12 DN², so SNR = μ_e / √(σ_d² + σ_q²/K² + μ_e).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.model.data import config_dir, read_csv_columns, read_toml
from uwlab.model.grid import WavelengthGrid

_REQUIRED = {
    "name": str, "pixel_size_um": float, "resolution_px": list, "bit_depth": int, "K_dn_per_e": float,
    "dark_offset_dn": float, "dark_noise_e": float, "saturation_e": float, "exposure_min_us": float,
    "exposure_max_us": float, "gain_min_db": float, "gain_max_db": float, "qe_csv": str,
}


@dataclass(frozen=True, eq=False)
class SensorProfile:
    """EMVA 1288 description of a sensor (values at 0 dB gain and `bit_depth` bits)."""

    name: str
    pixel_size_um: float
    resolution_px: tuple[int, int]
    bit_depth: int
    K_dn_per_e: float
    dark_offset_dn: float
    dark_noise_e: float
    saturation_e: float
    exposure_min_us: float
    exposure_max_us: float
    gain_min_db: float
    gain_max_db: float
    qe_nm: np.ndarray = field(repr=False)
    qe: dict = field(repr=False)
    color: bool = False
    dark_current_e_per_s: float = 0.0
    dsnu_e: float = 0.0
    prnu_percent: float = 0.0
    description: str = ""
    source: str = ""

    @property
    def pixel_area_m2(self) -> float:
        return (self.pixel_size_um * 1e-6) ** 2

    @property
    def size_m(self) -> tuple[float, float]:
        """Active area (x, y) [m]."""
        return tuple(n * self.pixel_size_um * 1e-6 for n in self.resolution_px)

    @property
    def diagonal_m(self) -> float:
        return float(np.hypot(*self.size_m))

    def qe_on(self, grid: WavelengthGrid, channel: str = "combined") -> np.ndarray:
        """η(λ) on the grid, linearly interpolated, zero outside the tabulated range."""
        key = "combined" if not self.color and channel == "combined" else channel
        if key not in self.qe:
            raise ConfigError("sensor.channel", channel, f"{self.name} has channels {', '.join(self.qe)}")
        return np.interp(grid.nm, self.qe_nm, self.qe[key], left=0.0, right=0.0)

    def gain_k(self, gain_db, bit_depth=None):
        """K = K₀ 10^(gain/20) 2^(bits − profile bits) [DN/e⁻]."""
        bits = self.bit_depth if bit_depth is None else bit_depth
        return self.K_dn_per_e * 10 ** (np.asarray(gain_db, float) / 20.0) * 2.0 ** (np.asarray(bits) - self.bit_depth)

    def dark_dn(self, bit_depth=None):
        bits = self.bit_depth if bit_depth is None else bit_depth
        return self.dark_offset_dn * 2.0 ** (np.asarray(bits) - self.bit_depth)


def response_dn(mu_e, k_dn_per_e, dark_dn, saturation_e, bit_depth):
    """(μ_y [DN], saturated flag) of the EMVA linear model with clipping at saturation and full scale."""
    mu_e = np.asarray(mu_e, float)
    full = 2.0 ** np.asarray(bit_depth) - 1
    raw = dark_dn + k_dn_per_e * mu_e
    mu_y = np.minimum(dark_dn + k_dn_per_e * np.minimum(mu_e, saturation_e), full)
    return mu_y, (mu_e >= saturation_e) | (raw >= full)


def snr(mu_e, dark_noise_e, k_dn_per_e):
    """EMVA 1288 SNR = μ_e / √(σ_d² + σ_q²/K² + μ_e) with σ_q² = 1/12 DN²."""
    mu_e = np.asarray(mu_e, float)
    return mu_e / np.sqrt(dark_noise_e**2 + (1.0 / 12.0) / np.asarray(k_dn_per_e, float) ** 2 + mu_e)


def _check(data: dict, path: Path) -> None:
    for key, kind in _REQUIRED.items():
        if key not in data:
            raise ConfigError(f"sensor profile {path.name}: {key}", None, "missing")
        if kind is float and not isinstance(data[key], (int, float)) or kind is int and not isinstance(data[key], int):
            raise ConfigError(f"sensor profile {path.name}: {key}", data[key], f"must be a {kind.__name__}")
    for key in ("pixel_size_um", "K_dn_per_e", "saturation_e", "bit_depth"):
        if not data[key] > 0:
            raise ConfigError(f"sensor profile {path.name}: {key}", data[key], "must be > 0")


@lru_cache(maxsize=64)
def _load(path: Path) -> SensorProfile:
    data = read_toml(path, "sensor.profile")
    _check(data, path)
    color = bool(data.get("color", False))
    columns = ("wavelength_nm", "red", "green", "blue", "combined") if color else ("wavelength_nm", "qe")
    table = read_csv_columns(path.parent / data["qe_csv"], columns, f"sensor profile {path.name}: qe_csv")
    qe = {c: table[c] for c in columns[1:]} if color else {"combined": table["qe"]}
    optional = ("dark_current_e_per_s", "dsnu_e", "prnu_percent", "description")
    return SensorProfile(
        name=data["name"], pixel_size_um=float(data["pixel_size_um"]),
        resolution_px=(int(data["resolution_px"][0]), int(data["resolution_px"][1])),
        bit_depth=int(data["bit_depth"]), K_dn_per_e=float(data["K_dn_per_e"]),
        dark_offset_dn=float(data["dark_offset_dn"]), dark_noise_e=float(data["dark_noise_e"]),
        saturation_e=float(data["saturation_e"]), exposure_min_us=float(data["exposure_min_us"]),
        exposure_max_us=float(data["exposure_max_us"]), gain_min_db=float(data["gain_min_db"]),
        gain_max_db=float(data["gain_max_db"]), qe_nm=table["wavelength_nm"], qe=qe, color=color,
        source=str(path), **{k: data[k] for k in optional if k in data},
    )


def available_profiles() -> list[str]:
    return sorted(p.stem for p in (config_dir() / "sensors").glob("*.toml"))


def load_sensor_profile(name: str, base: Path | None = None) -> SensorProfile:
    """A profile by name (`configs/sensors/<name>.toml`, case-insensitive) or by path to a TOML file."""
    path = Path(name)
    if path.suffix.lower() == ".toml":
        path = path if path.is_absolute() or base is None else base / path
        return _load(path.resolve())
    candidate = config_dir() / "sensors" / f"{name.lower()}.toml"
    if not candidate.exists():
        raise ConfigError("sensor.profile", name, f"unknown profile; available: {', '.join(available_profiles())}")
    return _load(candidate.resolve())
