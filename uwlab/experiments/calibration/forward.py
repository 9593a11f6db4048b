"""The forward model of a calibration: predicted dark-subtracted mean response of every measured point, for
many parameter vectors at once (emcee's ``vectorize=True``).

For point i of configuration k (a sweep's rig with its lens setting), the model's electron rate at the nominal
parameters, r_k (the mean over the ROI, axis-centred), is rescaled by the free parameters θ:

  r_k(θ) = r_k · ε · Ω(β₀)/Ω(β) · (M/M₀) · L_k · G_k(s)/G_k(s₀),
  μ_y,i − μ_y,dark,i = K_cam · 10^(g_i/20) · 2^(b_i − b_profile) · r_k(θ) · t_i,

with ε the light efficiency (true/rated flux), β the beam half-angle (Ω = 2π(1 − cos β) for the cone model,
π tan²β for the disk), M the target reflectance, s the attenuation scale and K the camera's system gain. L_k is the
configuration's lens group, shared by every camera carrying the same lens setting: with a lens, T/T₀, its
transmittance against the design's (``lens_transmittance:<label>``, one per lens setting, e.g.
``lens_transmittance:30mm-F2.0``, or ``lens_transmittance``, one for every lens); without one, F, the bare
sensor's irradiance against the model's π⟨L⟩ over its hemisphere (``bare_sensor_factor``, nominal 1: the light
the model does not render that reaches a bare sensor from oblique directions, and the sensor's own angular
response); each is 1 when it is not fitted. G_k(s) is the configuration's rate as a function of s alone:

- ``paper`` chain (`uwlab.model.chain`): G_k(s) = ∫ W_k(λ) e^(−s c(λ) D_k) dλ over the light → target → camera
  path D_k, times the mean vignetting over the ROI; every factor is exact for that chain;
- ``extended`` chain (`uwlab.model.extended`): the ROI's mean rate of target and veiling light (the veil grows
  with s too); β and M are not free there (the lights' geometry and the veil do not scale with them).

A camera characterised on the EMVA bench (the rig's ``sensor.characterised``, `uwlab fit --sensor`) brings its
measured response curve c(u) (`uwlab.model.sensor.ResponseCurve`): the prediction is multiplied by c(u), and the
curve's standard uncertainty, c_sd(u) × the prediction, adds to the point's noise in quadrature (data with their
uncertainty, not truths). The well fraction u = μ_e/μ_e,sat of the characterisation is taken in DN, where it does not
depend on how the fit splits K from the light's efficiency: u = (linear prediction) / (K μ_e,sat of the
characterised profile × 10^(g/20) 2^(b − its bits)), its linear-equivalent saturation signal at the point's gain
and bit depth (in `sigma`, u from the prediction itself: a relative error of c − 1, a few per cent of c_sd).

G_k is evaluated once on `S_GRID` (one vectorised evaluation of the chain) and interpolated by a cubic spline in
(ln s, ln G): within 1e-8 of the chain. Points taken with the light dimmed are scaled by the light's measured
relative output (`relative_flux`). A "no lens" point (f_number null) is a bare sensor: N = 0.5, T = 1, no
vignetting (`uwlab.model.optics.NO_LENS`); the extended chain integrates its whole field of view.

Colour: points with a ``channel`` column (`uwlab.experiments.dataset.channel_view`: one colour channel of Bayer
points, its own signal, variances and ``pixels``) are predicted with that channel's QE (the design's
``sensor.channel``, the colour profile's red, green or blue column), each channel of a sweep a configuration of its
own; K is the camera's, shared by its channels. Without it, a Bayer point's whole-mosaic mean is predicted with the
profile's ``combined`` QE, the mean response of one Bayer cell.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import theilslopes
import pandas as pd
from scipy.interpolate import CubicSpline

from uwlab.model.config import rate_design_sections
from uwlab.errors import ConfigError
from uwlab.model import extended
from uwlab.model.config import apply_override
from uwlab.model.build import build_design
from uwlab.model.chain import (
    beam_half_angle_rad,
    housing_transmittance,
    electron_rate_at_radius,
    light_distance_m,
    on_axis_electron_rate,
    paper_beam_model,
)
from uwlab.model.design import Design
from uwlab.model.sensor import (
    ResponseCurve,
    SensorProfile,
    load_sensor_profile,
    response_ratio,
    response_ratio_sd,
)
from uwlab.model.weights import broadband_factor, spectral_weights
from uwlab.model.optics import NO_LENS, LensSetting

SHARED = (
    "light_efficiency",
    "beam_half_angle_deg",
    "attenuation_scale",
    "reflectance",
    "lens_transmittance",
    "bare_sensor_factor",
    "discrepancy",
    "config_discrepancy",
)
NOT_EXTENDED = ("beam_half_angle_deg", "reflectance")
PER_CAMERA = ("K_dn_per_e",)
PER_LENS = "lens_transmittance"  # lens_transmittance:<LensSetting label>, one per lens setting
BARE = "bare_sensor_factor"
MODELS = ("paper", "extended")
REQUIRED_COLUMNS = (
    "sweep_id",
    "exposure_us",
    "gain_db",
    "f_number",
    "focal_length_mm",
    "bit_depth",
    "sensor_profile",
    "signal_dn",
    "temporal_var_dn2",
    "frames",
    "roi_w",
    "roi_h",
    "saturated",
)
PARAMETER_LABELS = {
    "light_efficiency": "light efficiency (true / rated flux)",
    "beam_half_angle_deg": "beam half-angle in water [°]",
    "attenuation_scale": "attenuation scale (× the water's c)",
    "reflectance": "target reflectance",
    "lens_transmittance": "lens transmittance",
    "bare_sensor_factor": "bare sensor's irradiance / the model's π⟨L⟩",
    "discrepancy": "discrepancy within a configuration",
    "config_discrepancy": "discrepancy between configurations (τ)",
}
PERCENT_PARAMETERS = ("discrepancy", "config_discrepancy")
S_GRID = np.geomspace(0.02, 50.0, 200)
ROI_SAMPLES = 4


@dataclass(frozen=True)
class Transmission:
    """G_k(s)/G_k(s₀) of every configuration k: one vector-valued cubic spline of ln G in ln s over `S_GRID` (NaN
    outside it)."""

    spline: CubicSpline
    log_g0: np.ndarray

    @classmethod
    def from_values(cls, g: np.ndarray, s0: float) -> Transmission:
        """From G on `S_GRID`, shape (len(S_GRID), n_config), normalised at the nominal scale s0."""
        spline = CubicSpline(np.log(S_GRID), np.log(g), axis=0)
        return cls(spline, spline(np.log(s0)))

    def __call__(self, s) -> np.ndarray:
        """G_k(s)/G_k(s₀) for scales s of shape (n,): shape (n, n_config)."""
        log_s = np.log(np.asarray(s, float))
        lo, hi = self.spline.x[0], self.spline.x[-1]
        inside = ((log_s >= lo) & (log_s <= hi))[:, None]
        held = np.minimum(np.maximum(log_s, lo), hi)  # np.clip's values, without its argument checks
        return np.where(inside, np.exp(self.spline(held) - self.log_g0), np.nan)


@dataclass
class ForwardModel:
    """Per-point constants and per-configuration terms of a calibration data set."""

    names: tuple[str, ...]
    nominal: dict[str, float]
    y: np.ndarray
    sigma_meas: np.ndarray
    effective_exposure_s: np.ndarray  # per point: t · relative light output · 10^(g/20) 2^(b − b_profile) [s]
    config: np.ndarray  # configuration index per point
    camera: np.ndarray  # camera (sensor profile) index per point
    cameras: tuple[str, ...]
    nominal_rate_e_per_s: np.ndarray  # per configuration: mean rate over the ROI at nominal θ [e⁻/s]
    has_lens: np.ndarray  # per configuration
    lens_groups: tuple[str, ...]  # per configuration: the parameter of its lens group (L_k in the docstring)
    omega_cone: bool
    kind: str  # "paper" or "extended"
    transmission: Transmission  # G_k(s)/G_k(s₀) of every configuration
    designs: list[Design] = field(repr=False, default_factory=list)
    points: pd.DataFrame = field(repr=False, default=None)
    # per point: 1 / the characterised linear-equivalent saturation signal [1/DN] (0 for a camera without a
    # characterisation), and each camera's measured response curve (None: the linear sensor)
    well_fraction_per_dn: np.ndarray | None = field(repr=False, default=None)
    responses: tuple[ResponseCurve | None, ...] = ()

    @property
    def n_config(self) -> int:
        return len(self.designs)

    @cached_property
    def membership(self) -> np.ndarray:
        """(n_points, n_config) indicator of each point's configuration."""
        out = np.zeros((self.config.size, self.n_config))
        out[np.arange(self.config.size), self.config] = 1.0
        return out

    def index(self, name: str) -> int:
        return self.names.index(name)

    @cached_property
    def _columns(self) -> dict[str, int]:
        """Each free parameter's column in θ."""
        return {name: index for index, name in enumerate(self.names)}

    def parameter(self, theta: np.ndarray, name: str) -> np.ndarray:
        """Column `name` of θ (shape (n_walkers,)), or its nominal value when the parameter is fixed."""
        column = self._columns.get(name)
        if column is not None:
            return theta[:, column]
        return np.full(theta.shape[0], self.nominal[name])

    def _gather(self, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """How `_per_column` finds the parameters `names`: (θ's column of each, 0 for a fixed one; which are free,
        None when all are; their nominal values)."""
        columns = np.array([self._columns.get(name, 0) for name in names], dtype=np.intp)
        free = np.array([name in self._columns for name in names], dtype=bool)
        return columns, None if free.all() else free, np.array([self.nominal[name] for name in names])

    @staticmethod
    def _per_column(theta: np.ndarray, gathered: tuple[np.ndarray, np.ndarray | None, np.ndarray]) -> np.ndarray:
        """Parameters of every row of θ, shape (n_walkers, len(names)), as `parameter` gives them one by one (θ's
        column, or the nominal value of a fixed one), in one fancy index; `gathered` from `_gather`."""
        columns, free, nominal = gathered
        if free is None:
            return theta[:, columns]
        return np.where(free, theta[:, columns], nominal)

    @cached_property
    def _lookups(self) -> tuple[tuple, tuple, np.ndarray]:
        """Parameter-independent terms of `predict` and `sigma`, computed once: (`_gather` of each configuration's
        lens-group parameter, `_gather` of each point's K, the measurement variance σ²_meas per point)."""
        k_names = tuple(f"K_dn_per_e:{self.cameras[c]}" for c in self.camera)
        return self._gather(self.lens_groups), self._gather(k_names), self.sigma_meas**2

    def shape(self, theta: np.ndarray) -> np.ndarray:
        """The nonlinear shared factors relative to nominal, per configuration, shape (n_walkers, n_config):
        beam concentration (cone: solid-angle ratio; disk: tan² ratio; paper chain) × G_k(s)/G_k(s₀)."""
        theta = np.atleast_2d(theta)
        g = self.transmission(self.parameter(theta, "attenuation_scale"))
        if self.kind == "extended":
            return g
        beta = np.radians(self.parameter(theta, "beam_half_angle_deg"))[:, None]
        beta0 = np.radians(self.nominal["beam_half_angle_deg"])
        if self.omega_cone:
            beam = (1 - np.cos(beta0)) / (1 - np.cos(beta))
        else:
            beam = np.tan(beta0) ** 2 / np.tan(beta) ** 2
        return beam * g

    def mean_log(self, shape: np.ndarray) -> np.ndarray:
        """ln of a `shape` averaged over the points (each configuration weighted by its points), (n_walkers,)."""
        return np.log(shape) @ self._config_share

    @cached_property
    def _config_share(self) -> np.ndarray:
        """Each configuration's share of the points."""
        return np.bincount(self.config, minlength=self.n_config) / self.config.size

    @cached_property
    def _curves(
        self,
    ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...], tuple[np.ndarray, ...], np.ndarray | None]:
        """Each point's measured response curve as per-point arrays, so that every camera's curve is evaluated in one
        pass: (lower, upper end of its `fraction_range`; its (a, b); its covariances (caa, cab, cbb); which points
        have a curve, None when all do). A point without one gets zeros."""
        n = self.camera.size
        lo, hi, a, b, caa, cab, cbb = (np.zeros(n) for _ in range(7))
        covered = np.zeros(n, dtype=bool)
        for index, curve in enumerate(self.responses):
            if curve is not None:
                mine = self.camera == index
                covered[mine] = True
                lo[mine], hi[mine] = curve.fraction_range
                a[mine], b[mine] = curve.a, curve.b
                (caa[mine], cab[mine]), (_, cbb[mine]) = curve.covariance
        return lo, hi, (a, b), (caa, cab, cbb), None if covered.all() else covered

    def predict(self, theta: np.ndarray, shape: np.ndarray | None = None) -> np.ndarray:
        """Predicted dark-subtracted mean [DN], shape (n_walkers, n_points); `shape` = `self.shape(theta)` when the
        caller has it already."""
        theta = np.atleast_2d(theta)
        shape = self.shape(theta) if shape is None else shape
        # a fixed parameter is its nominal value, a scalar: the products' bits are those with a column of it
        p = lambda name: theta[:, self._columns[name], None] if name in self._columns else self.nominal[name]  # noqa: E731
        groups, k, _ = self._lookups
        lens = self._per_column(theta, groups) / groups[2]
        rate = (
            self.nominal_rate_e_per_s[None, :]
            * p("light_efficiency")
            * p("reflectance")
            / self.nominal["reflectance"]
            * lens
            * shape
        )
        linear = self._per_column(theta, k) * self.effective_exposure_s[None, :] * rate[:, self.config]
        if self.well_fraction_per_dn is None:
            return linear
        return linear * self._response(linear * self.well_fraction_per_dn[None, :], "ratio", 1.0)

    def _response(self, fraction: np.ndarray, what: str, linear: float) -> np.ndarray:
        """c(u) ("ratio") or c_sd(u) ("ratio_sd") of each point's camera at well fractions `fraction` (walkers,
        points); `linear` where a camera has no curve."""
        lo, hi, ratio, ratio_sd, covered = self._curves
        u = np.minimum(np.maximum(fraction, lo), hi)  # np.clip's values, without its argument checks
        out = response_ratio(u, *ratio) if what == "ratio" else response_ratio_sd(u, *ratio_sd)
        return out if covered is None else np.where(covered, out, linear)

    def sigma(self, theta: np.ndarray, prediction: np.ndarray) -> np.ndarray:
        """Per-point standard deviation: measurement noise of the ROI mean ⊕ fractional within-configuration
        discrepancy (the between-configuration discrepancy is in `uwlab.experiments.calibration.fit`) ⊕ the
        uncertainty of a measured response curve (module docstring)."""
        delta = self.parameter(np.atleast_2d(theta), "discrepancy")[:, None]
        variance = self._lookups[2] + (delta * prediction) ** 2
        if self.well_fraction_per_dn is not None:
            fraction = prediction * self.well_fraction_per_dn[None, :]
            variance = variance + (prediction * self._response(fraction, "ratio_sd", 0.0)) ** 2
        return np.sqrt(variance)


def parameter_label(name: str) -> str:
    """A free parameter in words, e.g. ``system gain K of IMX250M [DN/e⁻]`` for ``K_dn_per_e:imx250m``."""
    if name.startswith("K_dn_per_e:"):
        return f"system gain K of {name.split(':', 1)[1].upper()} [DN/e⁻]"
    if name.startswith(f"{PER_LENS}:"):
        return f"transmittance of the {name.split(':', 1)[1]} lens"
    return PARAMETER_LABELS.get(name, name)


def _roi_vignetting(design: Design, roi_w: float, roi_h: float) -> float:
    """Mean relative rate over an axis-centred ROI of roi_w × roi_h pixels (midpoint rule, 16 × 16)."""
    pitch = design.sensor.pixel_size_um * 1e-6
    u = (np.arange(16) + 0.5) / 16
    r = np.hypot.outer(u * roi_w * pitch / 2, u * roi_h * pitch / 2).ravel()
    rates = electron_rate_at_radius(design, np.concatenate([[0.0], r]))
    return float(rates[1:].mean() / rates[0])


def _paper_rates(design: Design, lens: bool, roi_w: float, roi_h: float) -> tuple[float, np.ndarray]:
    """(nominal ROI rate, G(S_GRID)) of the paper chain: on-axis rate × ROI vignetting; the path integral."""
    weights = spectral_weights(design)
    path_m = float(light_distance_m(design) + design["operation.altitude_m"])
    vignetting = _roi_vignetting(design, roi_w, roi_h) if lens else 1.0
    return float(on_axis_electron_rate(design)) * vignetting, weights.table(S_GRID * path_m, 2)


def extended_roi_rates(design: Design, lens: bool, roi_w: float, roi_h: float) -> tuple[np.ndarray, np.ndarray]:
    """(target, veiling light) mean electron rates [e⁻/s] of the extended chain over a `ROI_SAMPLES`² grid in an
    axis-centred ROI of roi_w × roi_h pixels (or the bare sensor's), broadcast over the design's arrays."""
    chain = extended.Chain(design, spectral_weights(design))
    port = housing_transmittance(design)
    if not lens:
        return chain.bare_rates(port)
    pitch = design.sensor.pixel_size_um * 1e-6
    u = (np.arange(ROI_SAMPLES) + 0.5) / ROI_SAMPLES - 0.5
    x, y = np.meshgrid(u * roi_w * pitch, u * roi_h * pitch)
    direct, veil = chain.pixel_rates(x.ravel(), y.ravel(), port, broadband_factor(design, "lens.transmittance"))
    return direct.mean(axis=-1), veil.mean(axis=-1)


def _extended_rates(design: Design, lens: bool, roi_w: float, roi_h: float) -> tuple[float, np.ndarray]:
    """(nominal ROI rate, rate(S_GRID)) of the extended chain: target and veiling light (`extended_roi_rates`)."""
    scaled = design.with_values(**{"water.attenuation_scale": S_GRID})
    target, veil = extended_roi_rates(design, lens, roi_w, roi_h)
    target_s, veil_s = extended_roi_rates(scaled, lens, roi_w, roi_h)
    return float(target + veil), target_s + veil_s


def _configuration_design(
    rig: dict,
    base_dir: Path | None,
    sensor: str,
    focal_length_mm,
    f_number,
    kind: str | None,
    channel: str | None = None,
) -> tuple[Design, bool]:
    raw: dict[str, Any] = {
        s: (list(v) if isinstance(v, list) else dict(v)) for s, v in rate_design_sections(rig).items()
    }
    raw.setdefault("sensor", {})["profile"] = sensor
    if channel is not None:
        raw["sensor"]["channel"] = channel
    raw["sensor"].pop("characterised", None)  # the response curve is the forward model's (`characterised_sensor`)
    has_lens = f_number is not None and np.isfinite(f_number)
    lens = LensSetting(float(focal_length_mm), float(f_number)) if has_lens else NO_LENS
    for key, value in lens.overrides().items():
        apply_override(raw, key, value)
    if kind is not None:
        apply_override(raw, "model.kind", kind)
    return build_design(raw, base_dir), has_lens


_REUSED: ContextVar[dict | None] = ContextVar("reused_configurations", default=None)


@contextmanager
def reused_configurations(evaluated: dict | None = None) -> Iterator[dict]:
    """Within the block, `build_forward_model` evaluates each configuration's chain (its design, nominal ROI rate
    and G(S_GRID): the costly part of a build) once and reuses it for every model that has the configuration, as
    the whole-data fit and the fits of a calibration's held-out folds do. Yields the store, which starts as a copy
    of `evaluated` (a store filled elsewhere, picklable: the whole-data fit's, sent to the folds' workers). The
    rigs' files are not read again meanwhile: the block is one calibration's
    (`uwlab.experiments.calibration.pipeline.assess`, `uwlab.experiments.calibration.parallel.run_folds`)."""
    store = dict(evaluated or {})
    token = _REUSED.set(store)
    try:
        yield store
    finally:
        _REUSED.reset(token)


def _configuration(
    rig: dict,
    base_dir: Path | None,
    sensor: str,
    focal_length_mm,
    f_number,
    kind: str | None,
    channel: str | None,
    roi: tuple[float, float],
) -> tuple[Design, bool, float, np.ndarray]:
    """(design, has a lens, nominal ROI rate, G(S_GRID)) of one configuration, from `reused_configurations`' store
    when it has them."""
    store = _REUSED.get()
    key = (
        json.dumps(rig, sort_keys=True, default=str),
        base_dir,
        sensor,
        focal_length_mm,
        f_number,
        kind,
        channel,
        *roi,
    )
    if store is not None and key in store:
        return store[key]
    design, lens = _configuration_design(rig, base_dir, sensor, focal_length_mm, f_number, kind, channel)
    rates = _extended_rates if design["model.kind"] == "extended" else _paper_rates
    found = (design, lens, *rates(design, lens, *roi))
    if store is not None:
        store[key] = found
    return found


def build_forward_model(
    points: pd.DataFrame,
    rigs: dict[str, dict],
    names: tuple[str, ...],
    base_dir: Path | None = None,
    kind: str | None = None,
) -> ForwardModel:
    """Assemble the forward model for the points (contract columns) with the rigs {sweep_id: design config};
    `kind` ("paper" or "extended") replaces the rigs' [model] kind."""
    missing = [c for c in REQUIRED_COLUMNS if c not in points.columns]
    if missing:
        raise ConfigError("dataset", ", ".join(missing), "missing column(s) in points")
    if kind is not None and kind not in MODELS:
        raise ConfigError("--model", kind, f"must be one of {', '.join(MODELS)}")
    cameras = tuple(sorted(points["sensor_profile"].astype(str).unique()))
    labels = lens_labels(points)
    lensed = sorted({label for label in labels if label != NO_LENS.label})
    allowed = (set(SHARED) - {BARE}) | {f"{p}:{c}" for p in PER_CAMERA for c in cameras}
    allowed |= {f"{PER_LENS}:{label}" for label in lensed} | ({BARE} if NO_LENS.label in labels else set())
    for name in names:
        if name not in allowed:
            raise ConfigError(
                f"parameters.{name}", name, f"unknown parameter; this dataset allows {', '.join(sorted(allowed))}"
            )
    per_lens = [name for name in names if name.startswith(f"{PER_LENS}:")]
    if per_lens and PER_LENS in names:
        raise ConfigError(f"parameters.{PER_LENS}", PER_LENS, f"is one for every lens; {per_lens[0]} one lens's")
    key_columns = ["sweep_id", "sensor_profile", "focal_length_mm", "f_number"]
    if "channel" in points:
        key_columns.append("channel")
    keys = points[key_columns].astype(object).where(points.notna(), None)
    key_tuples = [tuple(row) for row in keys.itertuples(index=False)]
    unique = list(dict.fromkeys(key_tuples))
    config = np.array([unique.index(k) for k in key_tuples])
    designs: list[Design] = []
    has_lens: list[bool] = []
    groups: list[str] = []
    rate0: list[float] = []
    transmission: list[np.ndarray] = []
    for sweep_id, sensor, focal, f_number, *channel in unique:
        if sweep_id not in rigs:
            raise ConfigError("dataset", sweep_id, "no rig recorded for this sweep in metadata.json")
        rows = points[config == len(designs)]
        roi = (float(rows["roi_w"].median()), float(rows["roi_h"].median()))
        design, lens, nominal_rate, curve = _configuration(
            rigs[sweep_id], base_dir, sensor, focal, f_number, kind, channel[0] if channel else None, roi
        )
        designs.append(design)
        has_lens.append(lens)
        if not lens:
            groups.append(BARE)
        else:
            groups.append(f"{PER_LENS}:{LensSetting(float(focal), float(f_number)).label}" if per_lens else PER_LENS)
        rate0.append(nominal_rate)
        transmission.append(curve)
    kinds = {d["model.kind"] for d in designs}
    if len(kinds) > 1:
        raise ConfigError("model.kind", sorted(kinds), "all sweeps of one fit must use the same chain (see --model)")
    chain = kinds.pop()
    if chain == "extended":
        for name in NOT_EXTENDED:
            if name in names:
                raise ConfigError(f"parameters.{name}", name, "cannot be fitted with the extended model")
    first = designs[0]
    with_lens = next((d for d, lens in zip(designs, has_lens, strict=True) if lens), None)
    nominal = {
        "light_efficiency": 1.0,
        "beam_half_angle_deg": float(np.degrees(beam_half_angle_rad(first))),
        "attenuation_scale": float(first["water.attenuation_scale"]),
        "reflectance": _scalar(first, "target.reflectance"),
        "lens_transmittance": _scalar(with_lens, "lens.transmittance") if with_lens is not None else 1.0,
        "bare_sensor_factor": 1.0,
        "discrepancy": 0.0,
        "config_discrepancy": 0.0,
    }
    for design, lens, group in zip(designs, has_lens, groups, strict=True):
        if lens and group != PER_LENS:
            nominal[group] = _scalar(design, "lens.transmittance")
    camera = np.array([cameras.index(s) for s in points["sensor_profile"].astype(str)])
    profile_of: dict[str, SensorProfile] = {}
    for idx, design in enumerate(designs):
        profile_of.setdefault(unique[idx][1], design.sensor)
    for cam in cameras:
        nominal[f"K_dn_per_e:{cam}"] = profile_of[cam].K_dn_per_e
    profile_bits = np.array([profile_of[s].bit_depth for s in points["sensor_profile"].astype(str)])
    characterised = _characterised_sensors(rigs, unique, cameras, base_dir)
    flux = points["relative_flux"].to_numpy(float) if "relative_flux" in points else relative_flux(points)
    well_fraction = None
    if any(p is not None for p in characterised):
        well_fraction = np.zeros(len(points))
        for index, profile in enumerate(characterised):
            if profile is not None:
                mine = camera == index
                gain = points["gain_db"].to_numpy(float)[mine]
                bits = points["bit_depth"].to_numpy(float)[mine]
                well_fraction[mine] = 1.0 / (profile.saturation_e * profile.gain_k(gain, bits))
    n_pix = (
        points["pixels"].to_numpy(float)
        if "pixels" in points
        else points["roi_w"].to_numpy(float) * points["roi_h"].to_numpy(float)
    )
    var_mean = points["temporal_var_dn2"].to_numpy(float) / (points["frames"].to_numpy(float) * n_pix)
    if "dark_temporal_var_dn2" in points and "dark_frames" in points:
        dark = points["dark_temporal_var_dn2"].to_numpy(float) / (points["dark_frames"].to_numpy(float).clip(1) * n_pix)
        var_mean = var_mean + np.nan_to_num(dark)
    beam_model = {paper_beam_model(d) for d in designs}
    if len(beam_model) > 1:
        raise ConfigError("light.beam_model", sorted(beam_model), "all sweeps of one fit must share a beam model")
    return ForwardModel(
        names=tuple(names),
        nominal=nominal,
        y=points["signal_dn"].to_numpy(float),
        sigma_meas=np.sqrt(var_mean),
        effective_exposure_s=10 ** (points["gain_db"].to_numpy(float) / 20)
        * 2.0 ** (points["bit_depth"].to_numpy(float) - profile_bits)
        * points["exposure_us"].to_numpy(float)
        * 1e-6
        * flux,
        config=config,
        camera=camera,
        cameras=cameras,
        nominal_rate_e_per_s=np.array(rate0),
        has_lens=np.array(has_lens),
        lens_groups=tuple(groups),
        omega_cone=beam_model == {"cone"},
        kind=chain,
        transmission=Transmission.from_values(np.stack(transmission, axis=1), nominal["attenuation_scale"]),
        designs=designs,
        points=points.reset_index(drop=True),
        well_fraction_per_dn=well_fraction,
        responses=tuple(None if p is None else p.response for p in characterised),
    )


def lens_labels(points: pd.DataFrame) -> np.ndarray:
    """Each point's lens setting, as `LensSetting.label` (``no-lens`` for a bare sensor: f-number null)."""
    focal, f_number = points["focal_length_mm"].to_numpy(float), points["f_number"].to_numpy(float)
    return np.array(
        [
            LensSetting(float(f), float(n)).label if np.isfinite(n) else NO_LENS.label
            for f, n in zip(focal, f_number, strict=True)
        ],
        dtype=object,
    )


def lens_group_parameters(points: pd.DataFrame) -> set[str]:
    """The lens-group parameters of these points' configurations: ``bare_sensor_factor`` for bare sensors,
    ``lens_transmittance:<label>`` for each lens setting."""
    return {BARE if label == NO_LENS.label else f"{PER_LENS}:{label}" for label in lens_labels(points)}


def lens_transmittances(points: pd.DataFrame, rigs: dict[str, dict], base_dir: Path | None = None) -> dict[str, float]:
    """The design's broadband transmittance of each lens setting the points were taken with (bare sensors left out),
    {label: T}: the nominal values of the ``lens_transmittance:<label>`` parameters."""
    out: dict[str, float] = {}
    labels = lens_labels(points)
    for row, label in zip(points.itertuples(index=False), labels, strict=True):
        if label != NO_LENS.label and label not in out:
            design, _ = _configuration_design(
                rigs[row.sweep_id], base_dir, str(row.sensor_profile), row.focal_length_mm, row.f_number, None
            )
            out[label] = _scalar(design, "lens.transmittance")
    return out


def characterised_sensor(source: str, base_dir: Path | None = None) -> SensorProfile:
    """The profile of ``source``: a sensor profile TOML written by `uwlab emva characterize`, or its output folder
    (the one profile TOML in it); `ConfigError` on ``sensor.characterised`` unless it holds a measured response
    curve."""
    path = Path(source)
    if base_dir is not None and not path.is_absolute():
        path = base_dir / path
    if path.is_dir():
        found = sorted(p for p in path.glob("*.toml"))
        if len(found) != 1:
            raise ConfigError("sensor.characterised", source, f"holds {len(found)} profile TOMLs; name the one to use")
        path = found[0]
    if not path.exists():  # a FIFO or a device is there: the profile's reader refuses it for what it is
        raise ConfigError("sensor.characterised", source, "no such profile or `uwlab emva characterize` folder")
    profile = load_sensor_profile(str(path))
    if profile.response is None:
        raise ConfigError(
            "sensor.characterised", source, "has no [response] curve (characterise the camera with this uwlab)"
        )
    return profile


def _characterised_sensors(
    rigs: dict[str, dict],
    unique: list[tuple],
    cameras: tuple[str, ...],
    base_dir: Path | None,
) -> list[SensorProfile | None]:
    """Per camera, the characterised profile its rigs name (``sensor.characterised``), or None; one camera's
    sweeps must agree."""
    found: dict[str, str | None] = {}
    for sweep_id, sensor, *_ in unique:
        source = rigs[sweep_id].get("sensor", {}).get("characterised")
        if found.setdefault(sensor, source) != source:
            raise ConfigError("sensor.characterised", source, f"differs between the sweeps of camera {sensor}")
    return [None if found.get(c) is None else characterised_sensor(str(found[c]), base_dir) for c in cameras]


def relative_flux(points: pd.DataFrame) -> np.ndarray:
    """The light's output at each point relative to full output (level 1), from the spectrometer.

    The light's level→flux curve is not assumed: each point's irradiance is taken from the readings of its sweep,
    position and level, divided by the median of those values over all level-1 points at that position. Within a
    sweep at one level the readings follow a straight line in the point's place in the sweep (a robust Theil–Sen
    line, Sen 1968, J. Am. Stat. Assoc. 63, 1379: the median of the pairwise slopes), so a light that drifts while
    the sweep runs (an LED warming up) is followed, while the reading noise of a single point (a dimmed light is
    read-noise limited) stays out of the predictions; the points are taken at a steady pace, so their place stands
    for their time. With fewer than three points, or without ``point_index``, the group's median stands for all of
    them. The same normalisation, applied to the level-1 sweeps, removes a drift of the light's output between
    sweeps. Points all at level 1 without readings get 1.

    >>> points = pd.DataFrame({"light_level": [1.0] * 4, "irradiance_w_m2": [10.3, 10.1, 9.9, 9.7],
    ...                        "point_index": [0, 1, 2, 3]})
    >>> relative_flux(points).round(4).tolist()
    [1.03, 1.01, 0.99, 0.97]
    """
    levels = points["light_level"].to_numpy(float) if "light_level" in points else np.ones(len(points))
    readings = "irradiance_w_m2" in points and points["irradiance_w_m2"].notna().all()
    if np.all(levels == 1.0) and not readings:
        return np.ones(len(points))
    if not readings:
        raise ConfigError(
            "light_level",
            sorted(set(levels)),
            "points below full light need spectrometer irradiance (irradiance_w_m2) to scale the light's output",
        )
    position = (
        points["irradiance_position"].astype(str).to_numpy()
        if "irradiance_position" in points
        else np.full(len(points), "")
    )
    sweep = points["sweep_id"].astype(str).to_numpy() if "sweep_id" in points else np.full(len(points), "")
    irradiance = points["irradiance_w_m2"].to_numpy(float)
    place = points["point_index"].to_numpy(float) if "point_index" in points else None
    steady = np.empty(len(points))
    groups = pd.Series(np.arange(len(points))).groupby([sweep, position, levels]).indices
    for rows in groups.values():
        steady[rows] = _steady_reading(irradiance[rows], None if place is None else place[rows])
    out = np.empty(len(points))
    for pos in np.unique(position):
        here = position == pos
        reference = steady[here & (levels == 1.0)]
        if reference.size == 0:
            raise ConfigError(
                "light_level", pos, "no level-1 spectrometer reading at this position to normalise against"
            )
        out[here] = steady[here] / np.median(reference)
    return out


def _steady_reading(irradiance: np.ndarray, place: np.ndarray | None) -> np.ndarray:
    """The readings of one sweep at one level as a Theil–Sen line in ``place`` (three or more distinct places),
    else their median (`relative_flux`)."""
    if place is None or np.unique(place).size < 3:
        return np.full(irradiance.shape, np.median(irradiance))
    slope, intercept, *_ = theilslopes(irradiance, place)
    return intercept + slope * place


def _scalar(design: Design, dotted: str) -> float:
    value = design[dotted]
    if isinstance(value, str):
        raise ConfigError(dotted, value, "a fit needs a broadband number here, not a spectrum file")
    return float(value)
