"""A uwlab sweep dataset (docs: "Dataset contract") as EMVA 1288 photon-transfer input.

Photon-transfer points are the rows of one ``exposure`` or ``light-level`` sweep with the light on; their dark
statistics are the row's ``dark_*`` columns. Dark frames at other exposures (rows of kind ``dark`` of the same
camera and gain) join the dark series used for the dark current.

Photons per pixel, μ_p = A t_exp ∫ E(λ) λ/(h c) dλ (EMVA 1288 Release 4.0), take E from, in order:
an explicit override (`IrradianceOverride`: a number in W/m² at one wavelength, or a spectrum; for a
``light-level`` sweep it is the irradiance at ``light_level`` = 1, scaled by each row's ``light_level``), the
point's spectrometer spectrum (the dataset's ``spectra`` table), or its integrated ``irradiance_w_m2`` at the given
wavelength. Irradiance measured at the target (``irradiance_position = "target"``) is not the irradiance at
the sensor and is refused. The pixel area comes from ``pixel_size_um`` or from the dataset's sensor profile.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import PhotonTransfer, photons_per_pixel
from uwlab.model.data import read_csv_columns
from uwlab.model.photometry import photon_flux, photons_per_joule
from uwlab.model.sensor import SensorProfile, load_sensor_profile

SWEEP_KINDS = ("exposure", "light-level")
REQUIRED_COLUMNS = ("sweep_id", "point_index", "kind", "exposure_us", "light_on", "frames", "bit_depth",
                    "mean_dn", "temporal_var_dn2", "spatial_var_dn2", "dark_mean_dn", "dark_temporal_var_dn2",
                    "dark_spatial_var_dn2", "dark_frames", "gain_db")


@dataclass(frozen=True)
class IrradianceOverride:
    """Irradiance at the sensor replacing the dataset's: ``irradiance_w_m2`` at ``wavelength_nm``, or a
    spectrum (``spectrum_nm``, ``spectrum_w_m2_nm``)."""

    irradiance_w_m2: float | None = None
    wavelength_nm: float | None = None
    spectrum_nm: np.ndarray | None = None
    spectrum_w_m2_nm: np.ndarray | None = None

    @classmethod
    def from_csv(cls, path: str) -> IrradianceOverride:
        """A spectrum CSV with columns ``wavelength_nm``, ``irradiance_w_m2_nm`` (``#`` comment lines allowed)."""
        table = read_csv_columns(Path(path), ("wavelength_nm", "irradiance_w_m2_nm"), "--irradiance")
        return cls(spectrum_nm=table["wavelength_nm"], spectrum_w_m2_nm=table["irradiance_w_m2_nm"])

    def photon_irradiance(self) -> float:
        if self.spectrum_nm is not None:
            return float(photon_flux(self.spectrum_nm, self.spectrum_w_m2_nm))
        if self.wavelength_nm is None:
            raise ConfigError("--wavelength-nm", None, "required with a number for --irradiance")
        return float(self.irradiance_w_m2 * photons_per_joule(self.wavelength_nm))

    def mean_wavelength_nm(self) -> float | None:
        if self.spectrum_nm is not None:
            return photon_weighted_wavelength(self.spectrum_nm, self.spectrum_w_m2_nm)
        return self.wavelength_nm


def photon_weighted_wavelength(wavelength_nm, irradiance_w_m2_nm) -> float:
    """Mean wavelength weighted by the photon spectrum E(λ) λ."""
    nm = np.asarray(wavelength_nm, float)
    weight = np.asarray(irradiance_w_m2_nm, float) * nm
    return float(np.sum(weight * nm) / np.sum(weight))


def check_columns(points: pd.DataFrame, where: str) -> None:
    missing = [c for c in REQUIRED_COLUMNS if c not in points.columns]
    if missing:
        raise ConfigError(f"{where}: columns", ", ".join(missing), "missing from the dataset's points")


def select_sweep(points: pd.DataFrame, sweep_id: str | None) -> str:
    """The photon-transfer sweep to analyse: ``sweep_id`` or the only exposure/light-level sweep."""
    candidates = sorted(points.loc[points["kind"].isin(SWEEP_KINDS), "sweep_id"].unique())
    if sweep_id is not None:
        if sweep_id not in candidates:
            raise ConfigError("--sweep", sweep_id, f"not an exposure/light-level sweep; have {candidates or 'none'}")
        return sweep_id
    if len(candidates) != 1:
        raise ConfigError("--sweep", None, f"choose one photon-transfer sweep of {candidates}" if candidates
                          else "the dataset has no exposure or light-level sweep")
    return candidates[0]


def pixel_area_m2(rows: pd.DataFrame, pixel_size_um: float | None) -> float:
    if pixel_size_um is not None:
        return (pixel_size_um * 1e-6) ** 2
    names = rows["sensor_profile"].dropna().unique() if "sensor_profile" in rows else []
    if len(names) != 1:
        raise ConfigError("sensor_profile", list(names), "need one sensor profile in the sweep or --pixel-size-um")
    return load_sensor_profile(str(names[0])).pixel_area_m2


def named_profile(points: pd.DataFrame) -> SensorProfile | None:
    """The sensor profile named by the dataset, when exactly one known profile is named (else None)."""
    names = points["sensor_profile"].dropna().unique() if "sensor_profile" in points else []
    if len(names) != 1:
        return None
    try:
        return load_sensor_profile(str(names[0]))
    except ConfigError:
        return None


def _row_photon_irradiance(row, spectra: pd.DataFrame, wavelength_nm: float | None) -> tuple[float, float | None]:
    where = f"sweep {row.sweep_id} point {row.point_index}"
    if getattr(row, "irradiance_position", None) == "target":
        raise ConfigError(f"{where}: irradiance_position", "target",
                          "EMVA 1288 needs the irradiance at the sensor; pass --irradiance")
    spec = spectra[(spectra["sweep_id"] == row.sweep_id) & (spectra["point_index"] == row.point_index)]
    spec = spec[spec["position"] != "target"]
    if len(spec) >= 2:
        return (float(photon_flux(spec["wavelength_nm"], spec["irradiance_w_m2_nm"])),
                photon_weighted_wavelength(spec["wavelength_nm"], spec["irradiance_w_m2_nm"]))
    irradiance = getattr(row, "irradiance_w_m2", None)
    if irradiance is None or pd.isna(irradiance):
        raise ConfigError(f"{where}: irradiance_w_m2", None, "no spectrometer reading; pass --irradiance")
    if wavelength_nm is None:
        raise ConfigError(f"{where}: spectrum", None, "integrated irradiance without a spectrum needs --wavelength-nm")
    return float(irradiance * photons_per_joule(wavelength_nm)), wavelength_nm


def _photon_irradiances(rows: pd.DataFrame, spectra: pd.DataFrame, override: IrradianceOverride | None,
                        wavelength_nm: float | None) -> tuple[np.ndarray, float | None]:
    if override is not None:
        base = override.photon_irradiance()
        scale = np.where(rows["kind"] == "light-level", rows["light_level"].astype(float), 1.0)
        if np.any(~np.isfinite(scale)):
            raise ConfigError("light_level", None, "needed to scale --irradiance in a light-level sweep")
        return base * scale, override.mean_wavelength_nm()
    found = [_row_photon_irradiance(row, spectra, wavelength_nm) for row in rows.itertuples(index=False)]
    lams = [lam for _, lam in found if lam is not None]
    return np.array([e for e, _ in found]), float(np.mean(lams)) if lams else None


def _dark_series(points: pd.DataFrame, rows: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(exposure [s], dark mean [DN], dark temporal variance [DN²]) of all distinct dark measurements."""
    own = rows[["exposure_us", "dark_mean_dn", "dark_temporal_var_dn2"]].set_axis(["t", "m", "v"], axis=1)
    cam = rows["camera_id"].iloc[0] if "camera_id" in rows else None
    gain = rows["gain_db"].iloc[0]
    dark = points[(points["kind"] == "dark") & (points["gain_db"] == gain)]
    if cam is not None and "camera_id" in dark:
        dark = dark[dark["camera_id"] == cam]
    other = dark[["exposure_us", "mean_dn", "temporal_var_dn2"]].set_axis(["t", "m", "v"], axis=1)
    series = pd.concat([own, other]).dropna().astype(float).drop_duplicates()
    return series["t"].to_numpy() * 1e-6, series["m"].to_numpy(), series["v"].to_numpy()


def photon_transfer_from_points(points: pd.DataFrame, spectra: pd.DataFrame, *, sweep_id: str | None = None,
                                pixel_size_um: float | None = None, override: IrradianceOverride | None = None,
                                wavelength_nm: float | None = None, source: str = "") -> PhotonTransfer:
    """The `PhotonTransfer` of one sweep of a dataset's points/spectra tables (see the module docstring)."""
    check_columns(points, source or "dataset")
    sweep = select_sweep(points, sweep_id)
    rows = points[(points["sweep_id"] == sweep) & points["kind"].isin(SWEEP_KINDS) & (points["light_on"] == True)]  # noqa: E712
    if len(rows) == 0:
        raise ConfigError("sweep", sweep, "no points with the light on")
    no_dark = rows["dark_mean_dn"].isna() | rows["dark_temporal_var_dn2"].isna()
    if no_dark.any():
        first = rows[no_dark].iloc[0]
        raise ConfigError(f"sweep {sweep} point {first.point_index}: dark_mean_dn", None,
                          "no dark frames: EMVA 1288 needs dark statistics at every point")
    if rows["gain_db"].nunique(dropna=False) > 1:
        raise ConfigError(f"sweep {sweep}: gain_db", sorted(rows["gain_db"].unique()), "must be constant")
    e_p, lam = _photon_irradiances(rows, spectra, override, wavelength_nm)
    area = pixel_area_m2(rows, pixel_size_um)
    exposure_s = rows["exposure_us"].to_numpy(float) * 1e-6
    dark_t, dark_m, dark_v = _dark_series(points, rows)
    width = rows["roi_w"].dropna() if "roi_w" in rows else pd.Series(dtype=float)
    height = rows["roi_h"].dropna() if "roi_h" in rows else pd.Series(dtype=float)
    col = lambda name: rows[name].to_numpy(float)  # noqa: E731
    return PhotonTransfer(
        photons=photons_per_pixel(e_p, exposure_s, area), exposure_s=exposure_s,
        mean_dn=col("mean_dn"), temporal_var_dn2=col("temporal_var_dn2"), spatial_var_dn2=col("spatial_var_dn2"),
        frames=col("frames"), dark_mean_dn=col("dark_mean_dn"), dark_temporal_var_dn2=col("dark_temporal_var_dn2"),
        dark_spatial_var_dn2=col("dark_spatial_var_dn2"), dark_frames=col("dark_frames"),
        dark_exposure_s=dark_t, dark_series_mean_dn=dark_m, dark_series_var_dn2=dark_v,
        bit_depth=int(rows["bit_depth"].iloc[0]), width_px=int(width.iloc[0]) if len(width) else 0,
        height_px=int(height.iloc[0]) if len(height) else 0, pixel_area_m2=area, wavelength_nm=lam,
        gain_db=float(rows["gain_db"].iloc[0]), source=f"{source} sweep {sweep}".strip(),
    )
