"""A uwlab sweep dataset (docs: "Dataset contract") as EMVA 1288 photon-transfer input.

Photon-transfer points are the rows of one ``exposure`` or ``light-level`` sweep with the light on; their dark
statistics are the row's ``dark_*`` columns. Dark frames at other exposures (rows of kind ``dark`` of the same
camera and gain) join the dark series used for the dark current.

Photons per pixel, μ_p = A t_exp ∫ E(λ) λ/(h c) dλ (EMVA 1288 Release 4.0 Linear eq. 3), with E the irradiance *at
the sensor plane* (§6.4: a calibrated photodiode "put at the place of the image sensor"), taken from, in order: an
explicit override (`IrradianceOverride`: a number in W/m² at one wavelength, or a spectrum, both meant at the sensor
plane; for a ``light-level`` sweep it is the irradiance at ``light_level`` = 1, scaled by each row's
``light_level``), the point's spectrometer spectrum read at the ``sensor`` position (the dataset's ``spectra``
table), or its integrated ``irradiance_w_m2`` at the given wavelength when ``irradiance_position`` is ``sensor``.
Irradiance read anywhere else (``target``: on the board; ``camera``: π L_w in the water in front of the port, which
differs from the sensor plane by the port, the lens and n_w²) is refused with a one-line error: nothing converts it
silently. The pixel area comes from ``pixel_size_um`` or from the dataset's sensor profile.

Per point, the highpassed spatial variance split (``spatial_var_{row,col,pixel}_dn2`` and the ``dark_`` ones), the
saturated fraction, μ[0] − μ[1] and the temperature are taken when recorded. The dark series (for the dark noise and
the dark current, with its temperatures) is every dark measurement of the camera at the sweep's gain: the sweep's
own dark frames and the rows of ``dark`` sweeps.

Colour (EMVA 1288 Release 4.0 Linear §1.2: "each color channel" of a colour camera is characterised "as a sensor of
its own"): a sweep of raw Bayer frames records each channel's statistics (``<red|green|blue>_*`` columns, over the
channel's own sites; `uwlab.experiments.dataset.channel_view`). With a ``channel``, the photon transfer is that
channel's: its means, temporal variances, dark series and saturated fractions; μ_p per pixel is the same for every
channel (the irradiance on the sensor does not depend on the filter above a pixel), so η = R/K is the channel's QE at
the light's wavelength. The highpassed row/column/pixel split of a channel's spatial variance is taken on its sites'
planes (`uwlab.experiments.frames.stack`; green: the mean of its two planes'), so DSNU and PRNU are the channel's;
a dataset recorded before uwlab kept the split per channel gives none (the datasheet says why,
`uwlab.experiments.emva.transfer.CHANNEL_NO_SPLIT`). `load_dataset_inputs` gives every channel of a colour sweep.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.experiments.emva.dark import DarkSeries
from uwlab.experiments.emva.transfer import SheetInfo
from uwlab.experiments.emva.transfer import PhotonTransfer, SpatialSplit, photons_per_pixel
from uwlab.experiments.frames.frame import CHANNEL_NAMES
from uwlab.model.data import read_csv_columns
from uwlab.model.photometry import photon_flux, photons_per_joule
from uwlab.model.sensor import SensorProfile, load_sensor_profile

SWEEP_KINDS = ("exposure", "light-level")
REQUIRED_COLUMNS = (
    "sweep_id",
    "point_index",
    "kind",
    "exposure_us",
    "light_on",
    "frames",
    "bit_depth",
    "mean_dn",
    "temporal_var_dn2",
    "dark_mean_dn",
    "dark_temporal_var_dn2",
    "dark_frames",
    "gain_db",
)
SENSOR_PLANE = "sensor"
CHANNELS = tuple(CHANNEL_NAMES.values())
# The whole-ROI columns that have no per-channel counterpart: null in a channel's view (`channel_points`).
WHOLE_ROI_ONLY = ("mean_diff_dn",)


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

    @classmethod
    def given(cls, irradiance: float | str | os.PathLike[str] | None, wavelength_nm: float | None = None):
        """``uwlab emva characterize --irradiance``: a number [W/m²] (at `wavelength_nm`) or a spectrum CSV; None
        when not given. The number is checked against the plausibility limits (`uwlab.model.schema`)."""
        from uwlab.model.schema import IrradianceWM2, check

        if irradiance is None:
            return None
        try:
            value = float(irradiance)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            return cls.from_csv(os.fspath(irradiance))  # type: ignore[arg-type]
        return cls(irradiance_w_m2=check(IrradianceWM2, value, "--irradiance"), wavelength_nm=wavelength_nm)

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
        raise ConfigError(
            "--sweep",
            None,
            f"choose one photon-transfer sweep of {candidates}"
            if candidates
            else "the dataset has no exposure or light-level sweep",
        )
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


def _refuse_position(where: str, position) -> None:
    raise ConfigError(
        f"{where}: irradiance_position",
        position,
        "EMVA 1288 needs the irradiance at the sensor plane (Release 4.0 §6.4): read the spectrometer "
        "at the 'sensor' position (e.g. the bench rig configs/rigs/sim-emva-bench.toml) or pass "
        "--irradiance",
    )


def _row_photon_irradiance(row, spectra: pd.DataFrame, wavelength_nm: float | None) -> tuple[float, float | None]:
    where = f"sweep {row.sweep_id} point {row.point_index}"
    spec = spectra[(spectra["sweep_id"] == row.sweep_id) & (spectra["point_index"] == row.point_index)]
    at_sensor = spec[spec["position"] == SENSOR_PLANE]
    if len(at_sensor) >= 2:
        return (
            float(photon_flux(at_sensor["wavelength_nm"], at_sensor["irradiance_w_m2_nm"])),
            photon_weighted_wavelength(at_sensor["wavelength_nm"], at_sensor["irradiance_w_m2_nm"]),
        )
    position = getattr(row, "irradiance_position", None)
    if len(spec):
        _refuse_position(where, str(spec["position"].iloc[0]))
    if position != SENSOR_PLANE:
        _refuse_position(where, position)
    irradiance = getattr(row, "irradiance_w_m2", None)
    if irradiance is None or pd.isna(irradiance):
        raise ConfigError(f"{where}: irradiance_w_m2", None, "no spectrometer reading; pass --irradiance")
    if wavelength_nm is None:
        raise ConfigError(f"{where}: spectrum", None, "integrated irradiance without a spectrum needs --wavelength-nm")
    return float(irradiance * photons_per_joule(wavelength_nm)), wavelength_nm


def _photon_irradiances(
    rows: pd.DataFrame, spectra: pd.DataFrame, override: IrradianceOverride | None, wavelength_nm: float | None
) -> tuple[np.ndarray, float | None]:
    if override is not None:
        base = override.photon_irradiance()
        scale = np.where(rows["kind"] == "light-level", rows["light_level"].astype(float), 1.0)
        if np.any(~np.isfinite(scale)):
            raise ConfigError("light_level", None, "needed to scale --irradiance in a light-level sweep")
        return base * scale, override.mean_wavelength_nm()
    found = [_row_photon_irradiance(row, spectra, wavelength_nm) for row in rows.itertuples(index=False)]
    lams = [lam for _, lam in found if lam is not None]
    return np.array([e for e, _ in found]), float(np.mean(lams)) if lams else None


def _column(rows: pd.DataFrame, name: str) -> np.ndarray:
    """A float column, NaN where absent or null."""
    return pd.to_numeric(rows[name], errors="coerce").to_numpy(float) if name in rows else np.full(len(rows), np.nan)


def _split(rows: pd.DataFrame, prefix: str) -> SpatialSplit:
    return SpatialSplit(*(_column(rows, f"{prefix}spatial_var_{part}_dn2") for part in ("row", "col", "pixel")))


def sweep_channels(points: pd.DataFrame, sweep_id: str) -> tuple[str, ...]:
    """The colour channels of a sweep (`CHANNELS` when its points are raw Bayer frames with per-channel columns,
    else ())."""
    rows = points[points["sweep_id"] == sweep_id]
    bayer = rows["bayer"].notna().any() if "bayer" in rows else False
    recorded = "red_mean_dn" in rows and rows["red_mean_dn"].notna().all()
    return CHANNELS if bayer and recorded else ()


def channel_points(points: pd.DataFrame, sweep_id: str, channel: str) -> pd.DataFrame:
    """The sweep's rows and its dark rows (`dark_rows`) as the colour ``channel`` saw them
    (`uwlab.experiments.dataset.channel_view`), the whole-ROI columns without a per-channel counterpart
    (`WHOLE_ROI_ONLY`) null; a sweep without per-channel columns (monochrome) is refused (`ConfigError` on
    ``--channel``)."""
    from uwlab.experiments.dataset import channel_view

    if channel not in CHANNELS:
        raise ConfigError("--channel", channel, f"must be one of {', '.join(CHANNELS)}")
    own = points[points["sweep_id"] == sweep_id]
    lit = own[own["kind"].isin(SWEEP_KINDS)]
    darks = dark_rows(points, lit) if len(lit) else own.iloc[:0]
    selected = pd.concat([own, darks[darks["sweep_id"] != sweep_id]])
    if not sweep_channels(selected, sweep_id):
        raise ConfigError(
            "--channel",
            channel,
            f"sweep {sweep_id} has no per-channel statistics (a monochrome camera, or recorded before uwlab kept "
            "them): characterise it without --channel",
        )
    try:
        view = channel_view(selected, channel)
    except ConfigError as exc:
        raise ConfigError("--channel", channel, exc.reason) from None
    return view.assign(**{column: np.nan for column in WHOLE_ROI_ONLY if column in view})


def dark_rows(points: pd.DataFrame, rows: pd.DataFrame) -> pd.DataFrame:
    """The rows of dark sweeps taken with the camera and gain of the photon-transfer ``rows``."""
    cam = rows["camera_id"].iloc[0] if "camera_id" in rows else None
    dark = points[(points["kind"] == "dark") & (points["gain_db"] == rows["gain_db"].iloc[0])]
    if cam is not None and "camera_id" in dark:
        dark = dark[dark["camera_id"] == cam]
    return dark


def _dark_series(points: pd.DataFrame, rows: pd.DataFrame) -> DarkSeries:
    """Every distinct dark measurement of the sweep's camera at its gain: the sweep's own dark frames and the rows
    of dark sweeps (exposure [s], mean [DN], temporal variance [DN²], temperature [°C])."""
    columns = ["exposure_us", "m", "v", "temperature_c"]
    own = pd.DataFrame(
        {
            "exposure_us": _column(rows, "exposure_us"),
            "m": _column(rows, "dark_mean_dn"),
            "v": _column(rows, "dark_temporal_var_dn2"),
            "temperature_c": _column(rows, "temperature_c"),
        }
    )
    dark = dark_rows(points, rows)
    other = pd.DataFrame(
        {
            "exposure_us": _column(dark, "exposure_us"),
            "m": _column(dark, "mean_dn"),
            "v": _column(dark, "temporal_var_dn2"),
            "temperature_c": _column(dark, "temperature_c"),
        }
    )
    series = pd.concat([own, other])[columns].dropna(subset=columns[:3]).drop_duplicates()
    return DarkSeries(
        series["exposure_us"].to_numpy() * 1e-6,
        series["m"].to_numpy(),
        series["v"].to_numpy(),
        series["temperature_c"].to_numpy(float),
    )


def photon_transfer_from_points(
    points: pd.DataFrame,
    spectra: pd.DataFrame,
    *,
    sweep_id: str | None = None,
    pixel_size_um: float | None = None,
    override: IrradianceOverride | None = None,
    wavelength_nm: float | None = None,
    source: str = "",
    channel: str | None = None,
) -> PhotonTransfer:
    """The `PhotonTransfer` of one sweep of a dataset's points/spectra tables, or of one colour ``channel`` of it
    (see the module docstring)."""
    check_columns(points, source or "dataset")
    sweep = select_sweep(points, sweep_id)
    if channel is not None:
        points = channel_points(points, sweep, channel)
    rows = points[(points["sweep_id"] == sweep) & points["kind"].isin(SWEEP_KINDS) & (points["light_on"] == True)]  # noqa: E712
    if len(rows) == 0:
        raise ConfigError("sweep", sweep, "no points with the light on")
    no_dark = rows["dark_mean_dn"].isna() | rows["dark_temporal_var_dn2"].isna()
    if no_dark.any():
        first = rows[no_dark].iloc[0]
        raise ConfigError(
            f"sweep {sweep} point {first.point_index}: dark_mean_dn",
            None,
            "no dark frames: EMVA 1288 needs dark statistics at every point",
        )
    if rows["gain_db"].nunique(dropna=False) > 1:
        raise ConfigError(f"sweep {sweep}: gain_db", sorted(rows["gain_db"].unique()), "must be constant")
    e_p, lam = _photon_irradiances(rows, spectra, override, wavelength_nm)
    area = pixel_area_m2(rows, pixel_size_um)
    exposure_s = rows["exposure_us"].to_numpy(float) * 1e-6
    width = rows["roi_w"].dropna() if "roi_w" in rows else pd.Series(dtype=float)
    height = rows["roi_h"].dropna() if "roi_h" in rows else pd.Series(dtype=float)
    col = lambda name: rows[name].to_numpy(float)  # noqa: E731
    # pixels per frame of the statistics: a channel's sites, else the ROI's (0 when not recorded)
    sites = pd.to_numeric(rows["pixels"], errors="coerce").dropna() if channel is not None else pd.Series([])
    if channel is not None:
        pixels = int(sites.iloc[0]) if len(sites) else 0
    else:
        pixels = int(width.iloc[0]) * int(height.iloc[0]) if len(width) and len(height) else 0
    notes: tuple[str, ...] = ()
    if override is not None:
        notes = ("irradiance from --irradiance (taken to be at the sensor plane)",)
    if channel is not None:
        layout = rows["bayer"].dropna()
        notes += (
            f"the {channel} channel of the raw Bayer mosaic"
            + (f" ({layout.iloc[0]})" if len(layout) else "")
            + (f", {int(sites.iloc[0])} sites per frame" if len(sites) else "")
            + ", characterised as a sensor of its own (Release 4.0 Linear §1.2); μ_p per pixel is the same for "
            "every channel, η is this channel's at the light's wavelength",
        )
    return PhotonTransfer(
        photons=photons_per_pixel(e_p, exposure_s, area),
        exposure_s=exposure_s,
        mean_dn=col("mean_dn"),
        temporal_var_dn2=col("temporal_var_dn2"),
        frames=col("frames"),
        dark_mean_dn=col("dark_mean_dn"),
        dark_temporal_var_dn2=col("dark_temporal_var_dn2"),
        dark_frames=col("dark_frames"),
        spatial=_split(rows, ""),
        dark_spatial=_split(rows, "dark_"),
        dark=_dark_series(points, rows),
        bit_depth=int(rows["bit_depth"].iloc[0]),
        saturated_fraction=_column(rows, "saturated_fraction"),
        mean_diff_dn=_column(rows, "mean_diff_dn"),
        temperature_c=_column(rows, "temperature_c"),
        point_index=_column(rows, "point_index"),
        sweep_id=sweep,
        width_px=int(width.iloc[0]) if len(width) else 0,
        height_px=int(height.iloc[0]) if len(height) else 0,
        pixels=pixels,
        pixel_area_m2=area,
        wavelength_nm=lam,
        gain_db=float(rows["gain_db"].iloc[0]),
        source=f"{source} sweep {sweep}".strip() + (f", {channel} channel" if channel else ""),
        notes=notes,
        channel=channel,
    )


@dataclass(frozen=True)
class DatasetInput:
    """A dataset's photon transfer with what the outputs need besides: the sensor profile it names (or None), a
    camera name and the datasheet header."""

    transfer: PhotonTransfer
    profile: SensorProfile | None
    camera: str
    info: SheetInfo


def load_dataset_inputs(
    root,
    *,
    sweep_id: str | None = None,
    pixel_size_um: float | None = None,
    override: IrradianceOverride | None = None,
    wavelength_nm: float | None = None,
    channel: str | None = None,
) -> dict[str | None, DatasetInput]:
    """Open the dataset at ``root`` and build the `PhotonTransfer` of its sweep (`photon_transfer_from_points`): for
    a monochrome sweep ``{None: input}``; for a colour (raw Bayer) sweep one per channel, ``{"red": ..., "green":
    ..., "blue": ...}``, each channel a sensor of its own (Release 4.0 Linear §1.2), or only ``channel``'s. A
    ``channel`` on a monochrome sweep is refused (`ConfigError` on ``--channel``)."""
    from uwlab.experiments.dataset import Dataset

    dataset = Dataset.open(root)
    points = dataset.points()
    check_columns(points, f"dataset {root}")
    sweep = select_sweep(points, sweep_id)
    channels: tuple[str | None, ...] = (channel,) if channel is not None else (sweep_channels(points, sweep) or (None,))
    inputs = {}
    for one in channels:
        pt = photon_transfer_from_points(
            points,
            dataset.spectra(),
            sweep_id=sweep,
            pixel_size_um=pixel_size_um,
            override=override,
            wavelength_nm=wavelength_nm,
            source=f"dataset {root}",
            channel=one,
        )
        inputs[one] = _dataset_input(dataset, points, pt, one)
    return inputs


def load_dataset_input(root, *, channel: str | None = None, **options) -> DatasetInput:
    """The one `PhotonTransfer` of the dataset at ``root`` (`load_dataset_inputs`): of its monochrome sweep, or of
    the colour ``channel`` of its colour sweep (a colour sweep without ``channel`` is refused: `ConfigError` on
    ``--channel``)."""
    inputs = load_dataset_inputs(root, channel=channel, **options)
    if len(inputs) > 1:
        raise ConfigError(
            "--channel",
            None,
            f"a colour (raw Bayer) sweep: choose one of {', '.join(CHANNELS)} (each channel is a sensor of its own, "
            "EMVA 1288 Release 4.0 Linear §1.2)",
        )
    return next(iter(inputs.values()))


def _dataset_input(dataset, points: pd.DataFrame, pt: PhotonTransfer, channel: str | None) -> DatasetInput:
    camera = points["camera_model"].dropna() if "camera_model" in points else pd.Series(dtype=object)
    name = str(camera.iloc[0]) if len(camera) else "camera"
    device = (dataset.metadata.get("devices") or {}).get(pt.sweep_id, {}).get("camera") or {}
    model = device.get("model") or name
    info = SheetInfo(
        vendor=device.get("vendor") or "—",
        model=model if channel is None else f"{model}, {channel} channel",
        serial=device.get("serial") or "—",
        measured=dataset.metadata.get("started_utc") or "—",
        interface=device.get("backend") or "—",
        type_of_data="Single (simulated camera)" if dataset.metadata.get("sim") else "Single",
    )
    return DatasetInput(pt, named_profile(points), name if channel is None else f"{name}-{channel}", info)
