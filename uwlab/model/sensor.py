"""Image sensors: profiles and the EMVA 1288 linear camera model.

EMVA 1288 Release 4.0 (linear), §2: the mean number of electrons generated during the exposure is
μ_e = η μ_p with μ_p = A t_exp / (h c) ∫ E(λ) λ dλ photons per pixel; spectrally,
μ_e = (A t_exp / (h c)) ∫ E_s(λ) λ η(λ) dλ. The digital signal is μ_y = μ_y,dark + K μ_e, with system gain K
[DN/e⁻]; here K = K₀ · 10^(gain_dB/20) and both K₀ and μ_y,dark scale by 2^(bits − profile bits) at another
output bit depth. μ_e is clipped at the saturation capacity and μ_y at the full scale 2^bits − 1. Temporal noise
σ_y² = K² (σ_d² + μ_e) + σ_q², σ_q² = 1/12 DN², so SNR = μ_e / √(σ_d² + σ_q²/K² + μ_e).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Annotated, Literal
from pathlib import Path

import numpy as np
from pydantic import Field, PrivateAttr, StrictBool, model_validator

from uwlab.errors import ConfigError
from uwlab.model.data import config_dir, read_csv_columns, read_toml
from uwlab.model.grid import WavelengthGrid
from uwlab.model.schema import (
    BitDepth,
    ExposureUs,
    GainDb,
    NonEmptyText,
    PixelSizeUm,
    Schema,
    Text,
    invalid,
    parse,
    limits,
)

# Limits of the profile's EMVA 1288 quantities, wide enough for any area-scan sensor: outside them a value is in
# another unit (K in e⁻/DN or at another bit depth by orders of magnitude, σ_d in DN, …) or a typing error.
SystemGain = Annotated[float, limits(1e-4, 100.0, "DN/e-")]
Electrons = Annotated[float, limits(0.0, 1e8, "e-", hint="")]
ResolutionPx = Annotated[int, limits(1, 100000, "px", hint="", integer=True)]
DarkOffsetDn = Annotated[float, limits(0.0, 2.0**32, "DN", hint="")]
DarkCurrent = Annotated[float, limits(0.0, 1e6, "e-/s", hint="")]
Percent = Annotated[float, limits(0.0, 100.0, "%", hint="a percentage")]
Coefficient = Annotated[float, limits(-1.0, 1.0, "", hint="a fraction per well fraction")]
WellFraction = Annotated[float, limits(0.0, 1.5, "", hint="a fraction of the saturation capacity")]


class ResponseCurve(Schema):
    """A sensor's measured response relative to its linear response at zero signal (the ``[response]`` table of a
    profile characterised by ``uwlab emva characterize``; `uwlab.experiments.emva.response`).

    Convention: the dark-subtracted signal is c(u) × K μ_e with c(u) = 1 + a u + b u² and u = μ_e / μ_e,sat (the
    linear-equivalent electrons over the profile's saturation capacity); ``covariance`` is that of (a, b), so that a
    forward model carries the curve's uncertainty, var c(u) = J Σ Jᵀ with J = (u, u²). Valid over
    ``fraction_range`` (the measured signals); outside it c is held at its end values. EMVA 1288 Release 4.0
    Linear §6.9 measures the deviation from a line (the linearity error); this is that deviation modelled.

    Examples
    --------
    >>> curve = ResponseCurve(a=-0.01, b=0.0, covariance=((1e-8, 0.0), (0.0, 1e-8)), fraction_range=(0.0, 0.9))
    >>> curve.ratio(np.array([0.0, 0.5, 2.0])).tolist()
    [1.0, 0.995, 0.991]
    """

    a: Coefficient
    b: Coefficient
    covariance: tuple[tuple[float, float], tuple[float, float]]
    fraction_range: tuple[WellFraction, WellFraction]
    source: Text = ""

    def ratio(self, fraction: np.ndarray) -> np.ndarray:
        """c(u) at well fractions u (held at the ends of `fraction_range`)."""
        return response_ratio(np.clip(np.asarray(fraction, float), *self.fraction_range), self.a, self.b)

    def zero_signal_gain(self, k_photon_transfer: float, fit_fraction: float = 0.7) -> float:
        """The system gain at zero signal (the K of this convention) from the photon-transfer K of EMVA 1288
        Release 4.0 Linear §6.4, fitted over 0 … `fit_fraction` of saturation on a camera with this curve.

        With shot noise carried through the response, mean y = K μ_e c(u) and σ²_y = K² μ_e (d(μ_e c)/dμ_e)², so
        the photon-transfer slope dσ²_y/dy is K (c + 5u c′ + 2u² c″) = K (1 + 6a u + 15b u²); averaged over
        uniformly spaced points up to `fit_fraction`, the fitted K is K₀ (1 + 3a f + 5b f²).

        >>> curve = ResponseCurve(a=-0.01, b=0.0, covariance=((0.0, 0.0), (0.0, 0.0)), fraction_range=(0.0, 0.9))
        >>> round(curve.zero_signal_gain(0.979), 4)
        1.0
        """
        f = fit_fraction
        return k_photon_transfer / (1.0 + 3.0 * self.a * f + 5.0 * self.b * f**2)

    def ratio_sd(self, fraction: np.ndarray) -> np.ndarray:
        """The standard uncertainty of c(u)."""
        (caa, cab), (_, cbb) = self.covariance
        return response_ratio_sd(np.clip(np.asarray(fraction, float), *self.fraction_range), caa, cab, cbb)


def response_ratio(u: np.ndarray, a, b) -> np.ndarray:
    """c(u) = 1 + a u + b u² of `ResponseCurve` at well fractions u already held to its range; a, b scalars or arrays
    broadcasting with u (`uwlab.experiments.calibration.forward` evaluates every camera's curve in one pass)."""
    return 1.0 + a * u + b * u**2


def response_ratio_sd(u: np.ndarray, caa, cab, cbb) -> np.ndarray:
    """The standard uncertainty of c(u), √(J Σ Jᵀ) with J = (u, u²) and Σ = ((caa, cab), (cab, cbb)) (`ResponseCurve`),
    at well fractions u already held to its range; the covariances scalars or arrays broadcasting with u."""
    return np.sqrt(np.maximum(caa * u**2 + 2 * cab * u**3 + cbb * u**4, 0.0))


class SensorProfile(Schema):
    """EMVA 1288 description of a sensor (values at 0 dB gain and `bit_depth` bits): the schema of
    ``configs/sensors/*.toml``. The QE curve (``qe_csv``, relative to the file) is loaded with the profile
    (`qe_nm`, `qe`). Profiles compare and hash by identity."""

    name: NonEmptyText = Field(description="sensor name")
    description: Text = Field("", description="what the sensor is, cameras using it")
    color: StrictBool = Field(False, description="colour (Bayer) sensor: the QE CSV has red, green, blue, combined")
    bayer: Literal["RG", "GR", "GB", "BG"] = Field(
        "RG",
        description="colour filter layout of a colour sensor: the "
        "filters of the first row's first two pixels (PFNC; RG = RGGB)",
    )
    pixel_size_um: PixelSizeUm = Field(description="pixel pitch [µm]")
    resolution_px: tuple[ResolutionPx, ResolutionPx] = Field(description="active pixels [x, y]")
    bit_depth: BitDepth = Field(description="ADC bit depth the values refer to [bit]")
    K_dn_per_e: SystemGain = Field(description="system gain K at 0 dB [DN/e⁻]")
    K_dn_per_e_std: SystemGain | None = Field(None, description="standard uncertainty of K where measured [DN/e⁻]")
    dark_offset_dn: DarkOffsetDn = Field(description="mean dark level [DN]")
    dark_noise_e: Electrons = Field(description="temporal dark noise σ_d [e⁻]")
    saturation_e: Electrons = Field(description="saturation capacity μ_e,sat [e⁻]")
    exposure_min_us: ExposureUs = Field(description="shortest exposure [µs]")
    exposure_max_us: ExposureUs = Field(description="longest exposure [µs]")
    gain_min_db: GainDb = Field(description="lowest analog gain [dB]")
    gain_max_db: GainDb = Field(description="highest analog gain [dB]")
    qe_csv: NonEmptyText = Field(description="quantum efficiency CSV beside the profile")
    dark_current_e_per_s: DarkCurrent = Field(0.0, description="dark current [e⁻/s]")
    dsnu_e: Electrons = Field(0.0, description="dark signal nonuniformity DSNU [e⁻]")
    prnu_percent: Percent = Field(0.0, description="photo-response nonuniformity PRNU [%]")
    provenance: dict[str, str] = Field({}, description="where each value comes from")
    flags: dict[str, list[str]] = Field({}, description="keys that are corrected, assumed or measured")
    response: ResponseCurve | None = Field(None, description="measured response curve (EMVA); None: linear")
    _qe_nm: np.ndarray = PrivateAttr()
    _qe: dict = PrivateAttr()
    _source: str = PrivateAttr("")

    __eq__ = object.__eq__
    __hash__ = object.__hash__

    @model_validator(mode="after")
    def _ranges(self):
        if self.exposure_max_us <= self.exposure_min_us:
            raise invalid("exposure_max_us", self.exposure_max_us, "must exceed exposure_min_us")
        if self.gain_max_db < self.gain_min_db:
            raise invalid("gain_max_db", self.gain_max_db, "must be at least gain_min_db")
        return self

    @classmethod
    def from_toml(cls, path: Path) -> SensorProfile:
        """Read and validate a profile TOML and its QE CSV."""
        label = f"sensor profile {path.name}:"
        profile = parse(cls, read_toml(path, "sensor.profile"), label)
        columns = ("wavelength_nm", "red", "green", "blue", "combined") if profile.color else ("wavelength_nm", "qe")
        table = read_csv_columns(path.parent / profile.qe_csv, columns, f"{label} qe_csv")
        profile._qe_nm = table["wavelength_nm"]
        profile._qe = {c: table[c] for c in columns[1:]} if profile.color else {"combined": table["qe"]}
        profile._source = str(path)
        return profile

    @property
    def qe_nm(self) -> np.ndarray:
        """Wavelengths of the QE table [nm]."""
        return self._qe_nm

    @property
    def qe(self) -> dict[str, np.ndarray]:
        """η per channel ("combined"; colour sensors also "red", "green", "blue") on `qe_nm`."""
        return self._qe

    @property
    def source(self) -> str:
        """The profile file."""
        return self._source

    @property
    def pixel_area_m2(self) -> float:
        return (self.pixel_size_um * 1e-6) ** 2

    @property
    def size_m(self) -> tuple[float, float]:
        """Active area (x, y) [m]."""
        width, height = self.resolution_px
        return width * self.pixel_size_um * 1e-6, height * self.pixel_size_um * 1e-6

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


def snr(mu_e, dark_noise_e, k_dn_per_e, veil_e=None):
    """EMVA 1288 SNR = μ_e / √(σ_d² + σ_q²/K² + μ_e) with σ_q² = 1/12 DN²; with `veil_e`, electrons of light that
    carries no image of the target (veiling light) add their shot noise: μ_e / √(σ_d² + σ_q²/K² + μ_e + μ_veil)."""
    mu_e = np.asarray(mu_e, float)
    shot = mu_e if veil_e is None else mu_e + np.asarray(veil_e, float)
    return mu_e / np.sqrt(dark_noise_e**2 + (1.0 / 12.0) / np.asarray(k_dn_per_e, float) ** 2 + shot)


@lru_cache(maxsize=64)
def _load(path: Path) -> SensorProfile:
    return SensorProfile.from_toml(path)


def available_profiles() -> list[str]:
    return sorted(p.stem for p in (config_dir() / "sensors").glob("*.toml"))


def profile_path(name: str, base: Path | None = None) -> Path:
    """The file a ``sensor.profile`` value names: a path to a TOML file (relative to ``base``) or, for any other
    value, the name's file in ``configs/sensors`` (`load_sensor_profile` reads this file, and the explorer checks it
    before, `uwlab.explore.inputs`)."""
    path = Path(name)
    if path.suffix.lower() == ".toml":
        return path if path.is_absolute() or base is None else base / path
    return config_dir() / "sensors" / f"{name.lower()}.toml"


def load_sensor_profile(name: str, base: Path | None = None) -> SensorProfile:
    """A profile by name (`configs/sensors/<name>.toml`, case-insensitive) or by path to a TOML file."""
    path = profile_path(name, base)
    if Path(name).suffix.lower() != ".toml" and not path.exists():
        raise ConfigError("sensor.profile", name, f"unknown profile; available: {', '.join(available_profiles())}")
    return _load(path.resolve())
