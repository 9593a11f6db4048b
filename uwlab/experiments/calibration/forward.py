"""The forward model of a calibration: predicted dark-subtracted mean response of every measured point, for
many parameter vectors at once (emcee's ``vectorize=True``).

For point i of configuration k (a sweep's rig with its lens setting), the model's on-axis electron rate at the
nominal parameters, r_k = `uwlab.model.design.on_axis_electron_rate`, is rescaled analytically by the free
parameters θ (every factor below is exact for the chain in `uwlab.model.design`):

  r_k(θ) = r_k · ε · Ω(β₀)/Ω(β) · (M/M₀) · (T/T₀)^[lens] · G_k(s)/G_k(s₀) · v_k,
  G_k(s) = ∫ W_k(λ) exp(−s c(λ) D_k) dλ,   μ_y,i − μ_y,dark,i = K_cam · 10^(g_i/20) · 2^(b_i − b_profile) · r_k(θ) · t_i,

with ε the light efficiency (true/rated flux), β the beam half-angle (Ω = 2π(1 − cos β) for the cone model,
π tan²β for the disk), M the target reflectance, T the lens transmittance (absent without a lens), s the
attenuation scale over the light→target→camera path D_k, K the camera's system gain, and v_k the mean
vignetting over the ROI (an ROI centred on the axis). Points taken with the light dimmed are scaled by the
light's measured relative output (`relative_flux`). A "no lens" point (f_number null) is a bare sensor in the
board's radiance field: N = 0.5, T = 1, no vignetting (`uwlab.model.optics.NO_LENS`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.model.config import apply_override
from uwlab.model.design import (Design, beam_half_angle_rad, build_design, electron_rate_at_radius, light_distance_m,
                                on_axis_electron_rate, path_integrals, spectral_weights)
from uwlab.model.optics import NO_LENS, LensSetting

SHARED = ("light_efficiency", "beam_half_angle_deg", "attenuation_scale", "reflectance", "lens_transmittance",
          "discrepancy")
PER_CAMERA = ("K_dn_per_e",)
REQUIRED_COLUMNS = ("sweep_id", "exposure_us", "gain_db", "f_number", "focal_length_mm", "bit_depth", "sensor_profile",
                    "signal_dn", "temporal_var_dn2", "frames", "roi_w", "roi_h", "saturated")


@dataclass
class ForwardModel:
    """Per-point constants and per-configuration spectral terms of a calibration data set."""

    names: tuple[str, ...]
    nominal: dict[str, float]
    y: np.ndarray
    sigma_meas: np.ndarray
    effective_exposure_s: np.ndarray  # per point: t · relative light output · 10^(g/20) 2^(b − b_profile) [s]
    config: np.ndarray           # configuration index per point
    camera: np.ndarray           # camera (sensor profile) index per point
    cameras: tuple[str, ...]
    nominal_rate_e_per_s: np.ndarray  # per configuration: on-axis rate × ROI vignetting at nominal θ [e⁻/s]
    has_lens: np.ndarray         # per configuration
    omega_cone: bool
    weights_e: np.ndarray        # (n_config, n_λ)
    attenuation_per_m: np.ndarray  # (n_config, n_λ): beam attenuation c(λ) before the attenuation scale
    path_length_m: np.ndarray    # (n_config,): light → target → camera
    nominal_transmission: np.ndarray  # (n_config,): G_k(s₀)
    designs: list[Design] = field(repr=False, default_factory=list)
    points: pd.DataFrame = field(repr=False, default=None)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def parameter(self, theta: np.ndarray, name: str) -> np.ndarray:
        """Column `name` of θ (shape (n_walkers,)), or its nominal value when the parameter is fixed."""
        if name in self.names:
            return theta[:, self.names.index(name)]
        return np.full(theta.shape[0], self.nominal[name])

    def shape(self, theta: np.ndarray) -> np.ndarray:
        """The nonlinear shared factors relative to nominal, per configuration, shape (n_walkers, n_config):
        beam concentration (cone: solid-angle ratio; disk: tan² ratio) × water transmission G_k(s)/G_k(s₀), with
        G_k(s) = Σ_λ W_k(λ) exp(−s c(λ) D_k) (D_k the light→target→camera path)."""
        theta = np.atleast_2d(theta)
        beta = np.radians(self.parameter(theta, "beam_half_angle_deg"))[:, None]
        beta0 = np.radians(self.nominal["beam_half_angle_deg"])
        if self.omega_cone:
            beam = (1 - np.cos(beta0)) / (1 - np.cos(beta))
        else:
            beam = np.tan(beta0) ** 2 / np.tan(beta) ** 2
        s = self.parameter(theta, "attenuation_scale")[:, None, None]
        g = np.einsum("wkl,kl->wk", np.exp(-s * (self.path_length_m[:, None] * self.attenuation_per_m)[None]), self.weights_e)
        return beam * g / self.nominal_transmission[None, :]

    def mean_log(self, shape: np.ndarray) -> np.ndarray:
        """ln of a `shape` averaged over the points (each configuration weighted by its points), (n_walkers,)."""
        share = np.bincount(self.config, minlength=self.nominal_transmission.size) / self.config.size
        return np.log(shape) @ share

    def predict(self, theta: np.ndarray, shape: np.ndarray | None = None) -> np.ndarray:
        """Predicted dark-subtracted mean [DN], shape (n_walkers, n_points); `shape` = `self.shape(theta)` when the
        caller has it already."""
        theta = np.atleast_2d(theta)
        shape = self.shape(theta) if shape is None else shape
        p = lambda name: self.parameter(theta, name)[:, None]  # noqa: E731
        lens = np.where(self.has_lens[None, :], p("lens_transmittance") / self.nominal["lens_transmittance"], 1.0)
        rate = (self.nominal_rate_e_per_s[None, :] * p("light_efficiency") * p("reflectance") / self.nominal["reflectance"]
                * lens * shape)
        k = np.stack([self.parameter(theta, f"K_dn_per_e:{cam}") for cam in self.cameras], axis=1)
        return k[:, self.camera] * self.effective_exposure_s[None, :] * rate[:, self.config]

    def sigma(self, theta: np.ndarray, prediction: np.ndarray) -> np.ndarray:
        """Per-point standard deviation: measurement noise of the ROI mean ⊕ fractional model discrepancy."""
        delta = self.parameter(np.atleast_2d(theta), "discrepancy")[:, None]
        return np.sqrt(self.sigma_meas[None, :] ** 2 + (delta * prediction) ** 2)


def _roi_vignetting(design: Design, roi_w: float, roi_h: float) -> float:
    """Mean relative rate over an axis-centred ROI of roi_w × roi_h pixels (midpoint rule, 16 × 16)."""
    pitch = design.sensor.pixel_size_um * 1e-6
    u = (np.arange(16) + 0.5) / 16
    r = np.hypot.outer(u * roi_w * pitch / 2, u * roi_h * pitch / 2).ravel()
    rates = electron_rate_at_radius(design, np.concatenate([[0.0], r]))
    return float(rates[1:].mean() / rates[0])


def _configuration_design(rig: dict, base_dir: Path | None, sensor: str, focal_length_mm, f_number) -> tuple[Design, bool]:
    raw = {s: dict(v) for s, v in rig.items() if s != "sim"}
    raw.setdefault("sensor", {})["profile"] = sensor
    has_lens = f_number is not None and np.isfinite(f_number)
    lens = LensSetting(float(focal_length_mm), float(f_number)) if has_lens else NO_LENS
    for key, value in lens.overrides().items():
        apply_override(raw, key, value)
    raw.setdefault("operation", {}).pop("exposure_s", None)
    return build_design(raw, base_dir), has_lens


def build_forward_model(points: pd.DataFrame, rigs: dict[str, dict], names: tuple[str, ...],
                        base_dir: Path | None = None) -> ForwardModel:
    """Assemble the forward model for the points (contract columns) with the rigs {sweep_id: design config}."""
    missing = [c for c in REQUIRED_COLUMNS if c not in points.columns]
    if missing:
        raise ConfigError("dataset", ", ".join(missing), "missing column(s) in points")
    cameras = tuple(sorted(points["sensor_profile"].astype(str).unique()))
    allowed = set(SHARED) | {f"{p}:{c}" for p in PER_CAMERA for c in cameras}
    for name in names:
        if name not in allowed:
            raise ConfigError(f"parameters.{name}", name, f"unknown parameter; this dataset allows {', '.join(sorted(allowed))}")
    keys = points[["sweep_id", "sensor_profile", "focal_length_mm", "f_number"]].astype(object).where(points.notna(), None)
    key_tuples = [tuple(row) for row in keys.itertuples(index=False)]
    unique = list(dict.fromkeys(key_tuples))
    config = np.array([unique.index(k) for k in key_tuples])
    designs, has_lens, rate0, w_e, c, path, g0 = [], [], [], [], [], [], []
    for sweep_id, sensor, focal, f_number in unique:
        if sweep_id not in rigs:
            raise ConfigError("dataset", sweep_id, "no rig recorded for this sweep in metadata.json")
        design, lens = _configuration_design(rigs[sweep_id], base_dir, sensor, focal, f_number)
        rows = points[config == len(designs)]
        vignetting = _roi_vignetting(design, rows["roi_w"].median(), rows["roi_h"].median()) if lens else 1.0
        weights = spectral_weights(design)
        path_m = float(light_distance_m(design) + design["operation.altitude_m"])
        designs.append(design)
        has_lens.append(lens)
        rate0.append(float(on_axis_electron_rate(design)) * vignetting)
        w_e.append(weights.W[:, 2])
        c.append(weights.c)
        path.append(path_m)
        g0.append(float(path_integrals(weights, design["water.attenuation_scale"] * path_m)[2]))
    first = designs[0]
    with_lens = next((d for d, lens in zip(designs, has_lens) if lens), None)
    nominal = {
        "light_efficiency": 1.0,
        "beam_half_angle_deg": float(np.degrees(beam_half_angle_rad(first))),
        "attenuation_scale": float(first["water.attenuation_scale"]),
        "reflectance": _number(first, "target.reflectance"),
        "lens_transmittance": _number(with_lens, "lens.transmittance") if with_lens is not None else 1.0,
        "discrepancy": 0.0,
    }
    camera = np.array([cameras.index(s) for s in points["sensor_profile"].astype(str)])
    profile_of = {}
    for idx, design in enumerate(designs):
        profile_of.setdefault(unique[idx][1], design.sensor)
    for cam in cameras:
        nominal[f"K_dn_per_e:{cam}"] = profile_of[cam].K_dn_per_e
    profile_bits = np.array([profile_of[s].bit_depth for s in points["sensor_profile"].astype(str)])
    n_pix = points["roi_w"].to_numpy(float) * points["roi_h"].to_numpy(float)
    var_mean = points["temporal_var_dn2"].to_numpy(float) / (points["frames"].to_numpy(float) * n_pix)
    if "dark_temporal_var_dn2" in points and "dark_frames" in points:
        dark = points["dark_temporal_var_dn2"].to_numpy(float) / (points["dark_frames"].to_numpy(float).clip(1) * n_pix)
        var_mean = var_mean + np.nan_to_num(dark)
    flux = points["relative_flux"].to_numpy(float) if "relative_flux" in points else relative_flux(points)
    beam_model = {d["light.beam_model"] for d in designs}
    if len(beam_model) > 1:
        raise ConfigError("light.beam_model", sorted(beam_model), "all sweeps of one fit must share a beam model")
    return ForwardModel(
        names=tuple(names), nominal=nominal, y=points["signal_dn"].to_numpy(float), sigma_meas=np.sqrt(var_mean),
        effective_exposure_s=10 ** (points["gain_db"].to_numpy(float) / 20) * 2.0 ** (points["bit_depth"].to_numpy(float) - profile_bits)
        * points["exposure_us"].to_numpy(float) * 1e-6 * flux,
        config=config, camera=camera, cameras=cameras, nominal_rate_e_per_s=np.array(rate0), has_lens=np.array(has_lens),
        omega_cone=beam_model == {"cone"}, weights_e=np.array(w_e), attenuation_per_m=np.array(c), path_length_m=np.array(path),
        nominal_transmission=np.array(g0),
        designs=designs, points=points.reset_index(drop=True),
    )


def relative_flux(points: pd.DataFrame) -> np.ndarray:
    """The light's output at each point relative to full output (level 1), from the spectrometer.

    The light's level→flux curve is not assumed: the median irradiance of the points of one sweep, position and
    level is divided by the median irradiance of all level-1 points at that position. Taking the median over a
    sweep's points at one level (assumed steady over a sweep; each point's reading stays in the dataset) keeps the
    reading noise of a dimmed light (read-noise limited) out of the predictions. Points all at level 1 need no
    readings.
    """
    levels = points["light_level"].to_numpy(float) if "light_level" in points else np.ones(len(points))
    if np.all(levels == 1.0):
        return np.ones(len(points))
    if "irradiance_w_m2" not in points or points["irradiance_w_m2"].isna().any():
        raise ConfigError("light_level", sorted(set(levels)), "points below full light need spectrometer irradiance "
                          "(irradiance_w_m2) to scale the light's output")
    position = points["irradiance_position"].astype(str).to_numpy() if "irradiance_position" in points else np.full(
        len(points), "")
    sweep = points["sweep_id"].astype(str).to_numpy() if "sweep_id" in points else np.full(len(points), "")
    irradiance = pd.Series(points["irradiance_w_m2"].to_numpy(float))
    level_median = irradiance.groupby([sweep, position, levels]).transform("median").to_numpy()
    out = np.empty(len(points))
    for pos in np.unique(position):
        here = position == pos
        reference = irradiance.to_numpy()[here & (levels == 1.0)]
        if reference.size == 0:
            raise ConfigError("light_level", pos, "no level-1 spectrometer reading at this position to normalise against")
        out[here] = level_median[here] / np.median(reference)
    return out


def _number(design: Design, dotted: str) -> float:
    value = design[dotted]
    if isinstance(value, str):
        raise ConfigError(dotted, value, "a fit needs a broadband number here, not a spectrum file")
    return float(value)
