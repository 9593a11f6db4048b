"""The measurements an EMVA 1288 characterisation starts from: a photon-transfer sweep, its dark series and, when
recorded, the image stacks for the nonuniformity analysis; and the saturation point of the sweep.

Photons per pixel (EMVA 1288 Release 4.0 Linear eq. 3, General eq. 3): μ_p = A t_exp ∫ E(λ) λ/(h c) dλ with A the
pixel area and E the irradiance *at the sensor plane* (§6.4: "a calibrated photodiode put at the place of the image
sensor").

Saturation (Release 4.0 Linear §6.6, General §6.7, same words): "the mean gray value where the histogram of the gray
value distribution is not significantly cut-off", found by setting the exposure "just as high that between 0.1 –
0.2 % of the total number of pixels show the maximum value". With a sweep instead of an adjusted exposure, the
saturation point is the brightest point before the first one at which more than 0.2 % of the pixels reach the
camera's clip level — uwlab's one saturation rule (`uwlab.experiments.saturation`: the clip level, the 0.2 % point
criterion). Only when the sweep never reaches the clip level (or its saturated fractions are unknown) is the
saturation point the maximum of the temporal variance (the Release 3.1 practice, kept by the reference
implementation): the variance drops as soon as the clipped tail is cut off. The maximum is searched among the
points with at least half the largest signal and a positive dark-corrected variance, so that neither a disturbed
low-signal frame pair nor the flat, noisy tail past saturation (where the dark-corrected variance is negative) can
be taken for it. A maximum before the brightest of those points counts only when the variance then drops by more
than three standard errors of the difference of two estimates (each from P pixels and the point's frame pairs:
relative standard error √(2/(P·pairs)), for Gaussian noise): a variance still rising, with one point above its
successor by chance (a colour channel whose filter passes little of the light is the usual case), gives the brightest
point.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from uwlab.errors import ConfigError
from uwlab.experiments.emva.dark import DarkSeries
from uwlab.experiments.frames.stack import StackStatistics
from uwlab.experiments.saturation import POINT_SATURATED_FRACTION, point_saturated


def photons_per_pixel(photon_irradiance_m2_s, exposure_s, pixel_area_m2):
    """μ_p = A t_exp E_p [photons] (Release 4.0 Linear eq. 3) from the photon irradiance E_p [photons m⁻² s⁻¹]."""
    return np.asarray(photon_irradiance_m2_s, float) * np.asarray(exposure_s, float) * pixel_area_m2


@dataclass(frozen=True)
class SpatialSplit:
    """Per-point row, column and pixel parts of the highpassed spatial variance [DN²] (Release 4.0 Linear eq. 44;
    NaN where not recorded); their sum is the total s²_y (eq. 37)."""

    row: np.ndarray
    col: np.ndarray
    pixel: np.ndarray

    def __post_init__(self) -> None:
        for name in ("row", "col", "pixel"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), float))

    @classmethod
    def unknown(cls, n: int) -> SpatialSplit:
        return cls(np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan))

    @classmethod
    def of(cls, stats: list[StackStatistics]) -> SpatialSplit:
        parts = [(s.spatial.row, s.spatial.col, s.spatial.pixel) if s.spatial else (np.nan,) * 3 for s in stats]
        return cls(*np.array(parts, float).reshape(-1, 3).T)

    @property
    def total(self) -> np.ndarray:
        return self.row + self.col + self.pixel

    def part(self, name: str) -> np.ndarray:
        return self.total if name == "total" else getattr(self, name)

    def take(self, order: np.ndarray) -> SpatialSplit:
        return SpatialSplit(self.row[order], self.col[order], self.pixel[order])


@dataclass(frozen=True)
class NonuniformityStack:
    """The two image stacks of the nonuniformity analysis (Release 4.0 Linear §8): L bright frames near 50 % of
    saturation and L dark frames at the same exposure, as `StackStatistics` with their mean images."""

    bright: StackStatistics
    dark: StackStatistics
    photons: float
    exposure_s: float


PER_POINT = (
    "photons",
    "exposure_s",
    "mean_dn",
    "temporal_var_dn2",
    "frames",
    "dark_mean_dn",
    "dark_temporal_var_dn2",
    "dark_frames",
    "saturated_fraction",
    "mean_diff_dn",
    "temperature_c",
    "point_index",
)


@dataclass(frozen=True)
class PhotonTransfer:
    """Per-point statistics of one photon-transfer sweep (arrays of equal length, `PER_POINT`, plus the spatial
    splits), its dark series (every dark measurement of the camera at this gain, for the dark noise and dark
    current) and optionally the nonuniformity stacks.

    ``saturated_fraction``, ``mean_diff_dn``, ``temperature_c`` and ``point_index`` (the dataset row of each point,
    of sweep ``sweep_id``) may hold NaN where not recorded. ``channel``: the colour channel ("red", "green", "blue")
    of a raw Bayer sweep these statistics are of (None: the whole image of a monochrome camera).
    """

    photons: np.ndarray
    exposure_s: np.ndarray
    mean_dn: np.ndarray
    temporal_var_dn2: np.ndarray
    frames: np.ndarray
    dark_mean_dn: np.ndarray
    dark_temporal_var_dn2: np.ndarray
    dark_frames: np.ndarray
    spatial: SpatialSplit
    dark_spatial: SpatialSplit
    dark: DarkSeries
    bit_depth: int
    saturated_fraction: np.ndarray | None = None
    mean_diff_dn: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    point_index: np.ndarray | None = None
    sweep_id: str | None = None
    stack: NonuniformityStack | None = None
    width_px: int = 0
    height_px: int = 0
    pixels: int = 0  # pixels per frame the statistics are over (a colour channel: its sites); 0: unknown
    pixel_area_m2: float | None = None
    wavelength_nm: float | None = None
    gain_db: float = 0.0
    source: str = ""
    notes: tuple[str, ...] = field(default=())
    channel: str | None = None

    def __post_init__(self) -> None:
        n = len(np.asarray(self.photons))
        for name in PER_POINT:
            value = getattr(self, name)
            array = np.full(n, np.nan) if value is None else np.asarray(value, float)
            if array.shape != (n,):
                raise ConfigError(f"photon transfer {name}", array.shape, f"expected {n} values")
            object.__setattr__(self, name, array)

    def sorted(self) -> PhotonTransfer:
        """The same sweep ordered by increasing μ_p."""
        order = np.argsort(self.photons, kind="stable")
        per_point = {name: getattr(self, name)[order] for name in PER_POINT}
        return replace(self, **per_point, spatial=self.spatial.take(order), dark_spatial=self.dark_spatial.take(order))

    def with_note(self, note: str) -> PhotonTransfer:
        return replace(self, notes=(*self.notes, note))

    @property
    def signal_dn(self) -> np.ndarray:
        """μ_y − μ_y.dark [DN]."""
        return self.mean_dn - self.dark_mean_dn

    @property
    def signal_var_dn2(self) -> np.ndarray:
        """σ²_y − σ²_y.dark [DN²]."""
        return self.temporal_var_dn2 - self.dark_temporal_var_dn2

    @property
    def operating_temperature_c(self) -> float | None:
        """The median temperature of the sweep's points (None when not recorded)."""
        assert self.temperature_c is not None  # __post_init__ replaced a None by NaN
        known = self.temperature_c[np.isfinite(self.temperature_c)]
        return float(np.median(known)) if known.size else None


@dataclass(frozen=True)
class Saturation:
    """The saturation point of a sweep sorted by μ_p: its ``index``, the ``rule`` that chose it (``"0.2 % at the clip
    level"`` or ``"variance maximum"``) and the index of the variance maximum for comparison."""

    index: int
    rule: str
    variance_max_index: int


CHANNEL_NO_SPLIT = (
    "not computed for a colour channel: the dataset was recorded before uwlab kept each channel's highpassed "
    "row/column/pixel split (Release 4.0 §8.1's filters, on the planes of the channel's sites); record the sweep "
    "again"
)


def no_split_note(pt: PhotonTransfer) -> str:
    """Why DSNU and PRNU are not computed when the sweep has no highpassed spatial variances."""
    if pt.channel is not None:
        return f"DSNU and PRNU of the {pt.channel} channel {CHANNEL_NO_SPLIT}"
    return (
        "DSNU and PRNU not computed: no highpassed spatial variances (a ROI larger than 19 px a side "
        "and statistics recorded by this version of uwlab are needed)"
    )


RULE_CLIP = "0.2 % of pixels at the clip level (Release 4.0 §6.6)"
RULE_VARIANCE = "maximum of the temporal variance"


def variance_maximum_index(pt: PhotonTransfer) -> int:
    """Index of the largest temporal variance among the points with at least half the largest signal and a
    positive dark-corrected variance, unless the variance does not drop significantly after it (see the module
    docstring)."""
    signal, var = pt.signal_dn, pt.temporal_var_dn2
    candidates = np.flatnonzero((signal >= 0.5 * np.nanmax(signal)) & (pt.signal_var_dn2 > 0))
    if candidates.size == 0:
        raise ConfigError(
            "saturation",
            None,
            "no point of the upper half of the sweep has a dark-corrected temporal variance above zero",
        )
    best = int(candidates[np.argmax(var[candidates])])
    later = candidates[candidates > best]
    if later.size and pt.pixels > 0:
        pairs = max(1, int(pt.frames[best]) // 2)
        drop_se = np.sqrt(2.0) * np.sqrt(2.0 / (pt.pixels * pairs)) * var[best]
        if var[best] - np.min(var[later]) <= 3.0 * drop_se:
            return int(candidates[-1])
    return best


def saturation(pt: PhotonTransfer) -> Saturation:
    """The saturation point of ``pt`` (sorted by μ_p) by the module docstring's rule."""
    variance_max = variance_maximum_index(pt)
    fractions = pt.saturated_fraction
    assert fractions is not None  # PhotonTransfer.__post_init__ replaced a None by NaN
    if np.all(np.isfinite(fractions)):
        saturated = np.flatnonzero([point_saturated(f, POINT_SATURATED_FRACTION) for f in fractions])
        if saturated.size:
            if saturated[0] == 0:
                raise ConfigError(
                    "saturation",
                    f"{100 * fractions[0]:.2g} %",
                    "the darkest point of the sweep already has more than 0.2 % of its pixels at the clip level",
                )
            return Saturation(int(saturated[0]) - 1, RULE_CLIP, variance_max)
    return Saturation(variance_max, RULE_VARIANCE, variance_max)


def unsaturated_note(pt: PhotonTransfer, sat: Saturation) -> str | None:
    """A note when the sweep (sorted by μ_p) never reaches the clip level and its variance maximum is its brightest
    point: the saturation point is then only where the sweep stopped (Release 4.0 Linear §6.6 asks for the mean
    "where the histogram ... is not significantly cut-off"), so the figures taken there are lower bounds. A colour
    channel whose filter passes little of the light is the usual case."""
    fractions = pt.saturated_fraction
    assert fractions is not None  # PhotonTransfer.__post_init__ replaced a None by NaN
    if sat.rule != RULE_VARIANCE or sat.index != len(pt.photons) - 1 or not np.all(np.isfinite(fractions)):
        return None
    where = f" in the {pt.channel} channel" if pt.channel else ""
    fix = ", or light the channel at a wavelength its filter passes (Release 4.0 Linear §1.2)" if pt.channel else ""
    return (
        f"the sweep never reaches the clip level{where}: its brightest point is taken for saturation, so μ_p.sat, "
        f"μ_e.sat, SNR_max and the dynamic range are lower bounds; extend the exposures{fix}"
    )


def points_between(signal: np.ndarray, sat: int, lo: float, hi: float) -> np.ndarray:
    """Indices up to the saturation point whose signal lies in [lo, hi] × the saturation signal."""
    idx = np.arange(sat + 1)
    s = signal[idx]
    return idx[(s >= lo * signal[sat]) & (s <= hi * signal[sat])]


@dataclass(frozen=True)
class SpatialPoint:
    """The spatial variances [DN²] behind DSNU and PRNU (Release 4.0 Linear §8.3): ``bright`` near 50 % of
    saturation and ``dark``, each {"total", "row", "col", "pixel"}; μ_y.50 − μ_y.dark, μ_p.50, the number of frames
    averaged and where they come from."""

    bright: dict[str, float]
    dark: dict[str, float]
    signal_dn: float
    photons: float
    frames: int
    source: str


def half_saturation_index(pt: PhotonTransfer, sat: int) -> int:
    """Index (``pt`` sorted by μ_p) of the point at or below saturation nearest 50 % of the saturation signal."""
    signal = pt.signal_dn
    return int(np.argmin(np.abs(signal[: sat + 1] - 0.5 * signal[sat])))


def spatial_point(pt: PhotonTransfer, sat: int) -> SpatialPoint | None:
    """The nonuniformity stacks' variances when recorded (§8.2: L frames), else the sweep point nearest 50 % of
    saturation (§4.2: two frames suffice for the variances); None when neither has them."""
    s = pt.stack
    if s is not None and s.bright.spatial is not None and s.dark.spatial is not None:
        return SpatialPoint(
            s.bright.spatial.parts,
            s.dark.spatial.parts,
            s.bright.mean_dn - s.dark.mean_dn,
            s.photons,
            min(s.bright.frames, s.dark.frames),
            f"stacks of {s.bright.frames} bright and {s.dark.frames} dark frames",
        )
    i = half_saturation_index(pt, sat)
    parts = ("total", "row", "col", "pixel")
    bright = {p: float(pt.spatial.part(p)[i]) for p in parts}
    dark = {p: float(pt.dark_spatial.part(p)[i]) for p in parts}
    if not all(np.isfinite([*bright.values(), *dark.values()])):
        return None
    return SpatialPoint(
        bright,
        dark,
        float(pt.signal_dn[i]),
        float(pt.photons[i]),
        int(pt.frames[i]),
        f"sweep point {i} ({pt.frames[i]:.0f} frames, {100 * pt.signal_dn[i] / pt.signal_dn[sat]:.0f} % of saturation)",
    )


@dataclass(frozen=True)
class SheetInfo:
    """What the datasheet header and operation point say beyond the characterisation itself (the camera's
    identity from a descriptor's ``l`` lines or a dataset's metadata; kept here, not beside the datasheet's
    rendering, so that reading a measurement never loads matplotlib)."""

    vendor: str = "—"
    model: str = "—"
    serial: str = "—"
    measured: str = "—"
    type_of_data: str = "Single"
    interface: str = "—"
    extra: dict = field(default_factory=dict)
