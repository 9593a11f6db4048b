"""The underwater image-formation chain and the design operations, evaluated with numpy broadcasting.

On-axis chain (Billings, Iscar & Johnson-Roberson, "Parametric Design of Underwater Optical Systems", with the
corrections listed in the README): light → water → Lambertian target → water → port → lens → sensor.

1. Φe(λ) = count · Φv · S(λ) / (K_m ∫ S V dλ)                       [W/nm]   (uwlab.model.photometry)
2. cone: E_t = Φe / Ω · cos θi / d_L² · e^(−c d_L), Ω = 2π(1 − cos β);
   disk (the original tool): E_t = Φe / (π (d_L tan β)²) · e^(−c d_L)    [W/m²/nm]
3. c(λ) = (a + b) · attenuation_scale                                         (uwlab.model.water)
4. L_t = E_t M / π;  5. L_w = L_t e^(−c d_C);  6. L_a = L_w T_port / n_w²    [W/m²/sr/nm]
7. E_s = L_a T_lens π / (4 N²) cos⁴α                                          (uwlab.model.optics)
8. μ_e = A t / (h c) ∫ E_s λ η dλ;  μ_y = μ_y,dark + K μ_e (clipped)          (uwlab.model.sensor)

Every numeric parameter may be an array; arrays broadcast against each other (a Cartesian grid is an open mesh:
one axis per parameter), and each quantity is computed only over the axes it depends on. Spectral integrals
depend on the design only through the attenuating path length D = scale · (d_L + d_C), so they are evaluated
as exp(−D ⊗ c) @ W with W the fixed spectral weights (one matrix product, no per-wavelength loop).

Image average (reported beside the on-axis figure): the mean over the sensor of the per-pixel response, for a
flat target perpendicular to the optical axis at d_C and the light beside the camera aimed along its axis. A
pixel at image radius r looks along α_air = atan(r / f) in air and α_w in water (flat port: tan α_w =
tan α_air / n_w, the paraxial f_uw = n_w f mapping; dome: α_w = α_air). Its paths are d / cos α_w, the
incidence on the target is α_w (cone: irradiance ∝ cos³α_w), pixels outside the beam (α_w > β) get no light,
and the lens adds cos⁴α_air. The average is taken over a 16 × 16 midpoint grid on one sensor quadrant
(the geometry is symmetric) of the unclipped signal, then clipped like a single pixel. The samples' sum, of a
function of the image radius only, is taken through Gauss rules of the samples' radii (`uwlab.model.quadrature`)
where those match it to 5e-9, else sample by sample (`_image_sum`), or through per-geometry tables.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from uwlab.model import extended, focus, optics, quadrature
from uwlab.model import port as port_model
from uwlab.model.config import apply_override, load_raw, validate
from uwlab.model.data import resolve_path
from uwlab.model.grid import WavelengthGrid
from uwlab.model.photometry import photons_per_joule, radiant_per_lumen
from uwlab.model.schema import within
from uwlab.model.sensor import SensorProfile, load_sensor_profile, response_dn, snr
from uwlab.model.spectra import NAMED_SPECTRA, relative_spectrum
from uwlab.model.spectral_table import LogHermiteTable, SpectralTable, image_table
from uwlab.model.target import NAMED_REFLECTANCE, reflectance, transmittance
from uwlab.model.water import WATER_TYPES, scattering_parts, water_iop

IMAGE_SAMPLES_PER_AXIS = 16


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
        values = {s: list(v) if isinstance(v, list) else dict(v) for s, v in self.values.items()}
        for name, value in dotted.items():
            section, key = name.split(".")
            values[section][key] = value
        return replace(self, values=values)


def _resolve(value, base: Path | None, names: tuple[str, ...] = ()):
    """Names stay names; anything else that is a string is a path relative to the config file."""
    if isinstance(value, str) and value not in names:
        return str(resolve_path(value, base))
    return value


def build_design(raw: dict, base_dir: Path | None = None) -> Design:
    """Validate a raw config dict and resolve its data; raises ConfigError naming the offending key."""
    values = validate(raw)
    sp = values["spectral"]
    grid = WavelengthGrid(sp["start_nm"], sp["stop_nm"], sp["step_nm"])
    light, sensor_cfg = values["light"], values["sensor"]
    light["spectrum"] = _resolve(light["spectrum"], base_dir, NAMED_SPECTRA)
    values["water"]["type"] = _resolve(values["water"]["type"], base_dir, WATER_TYPES)
    refl = values["target"]["reflectance"]
    values["target"]["reflectance"] = NAMED_REFLECTANCE.get(refl, refl) if isinstance(refl, str) else refl
    values["target"]["reflectance"] = _resolve(values["target"]["reflectance"], base_dir)
    values["lens"]["transmittance"] = _resolve(values["lens"]["transmittance"], base_dir)
    sensor = load_sensor_profile(sensor_cfg["profile"], base_dir)
    if sensor_cfg["bit_depth"] is None:
        sensor_cfg["bit_depth"] = sensor.bit_depth
    within("sensor.gain_db", sensor_cfg["gain_db"], sensor.gain_min_db, sensor.gain_max_db, f"{sensor.name}'s range")
    exposure = values["operation"]["exposure_s"]
    if not isinstance(exposure, str):
        within(
            "operation.exposure_s",
            exposure,
            sensor.exposure_min_us * 1e-6,
            sensor.exposure_max_us * 1e-6,
            f"{sensor.name}'s range",
        )
    design = Design(values=values, grid=grid, sensor=sensor, base_dir=base_dir)
    spectral_weights(design)  # resolve spectra, water and curves now, so bad names fail before evaluation
    return design


def load_design(path: str | Path, overrides: dict | None = None) -> Design:
    """Read a design TOML, apply ``{"section.key": value}`` overrides, validate and resolve."""
    raw = load_raw(path)
    for dotted, value in (overrides or {}).items():
        apply_override(raw, dotted, value)
    return build_design(raw, Path(path).resolve().parent)


def _spectral_key(d: Design):
    return (
        d.grid,
        d["light.spectrum"],
        d["water.type"],
        _hashable(d["target.reflectance"]),
        _hashable(d["lens.transmittance"]),
        id(d.sensor),
        d["sensor.channel"],
        d["water.particle_scattering_per_m"],
        d["water.particle_scattering_exponent"],
    )


def _hashable(value):
    """Spectral inputs are named by their file; a broadband number (or grid array) is not part of the weights."""
    return value if isinstance(value, str) else "broadband"


@dataclass(frozen=True)
class SpectralWeights:
    """Fixed spectral factors of the chain on the grid.

    c: beam attenuation [1/m] (unscaled): the water type's plus the added particles' scattering. W: columns
    (target irradiance, sensor irradiance, electron rate) per unit luminous flux, with the spectral (tabulated)
    reflectance and lens transmittance folded in and trapezoidal weights applied, so that exp(−D c) @ W integrates
    over wavelength; then the photon rate of the source alone, × reflectance, × reflectance × lens transmittance
    (the stages of `light_budget`). `reflectance` and `lens_transmittance` are the spectral curves when given as
    files, else ones (broadband numbers stay outside). b_water, b_particles: the scattering coefficients [1/m]
    (the extended model's veiling light): pure water's molecular part of the water type's b, and its particle
    part plus the added particles' (`uwlab.model.water.scattering_parts`).
    """

    c: np.ndarray
    W: np.ndarray
    s_per_lm: np.ndarray
    reflectance: np.ndarray
    lens_transmittance: np.ndarray
    qe: np.ndarray
    b_water: np.ndarray
    b_particles: np.ndarray

    @cached_property
    def table(self) -> SpectralTable:
        """G(D) = exp(−D c) @ W at any path lengths, without a sum over wavelength per point."""
        return SpectralTable(self.c, self.W)

    @cached_property
    def electron_mean_rate_per_m(self) -> float:
        """c̄ = −d ln G_e/dD at D = 0 = Σ W_e c / Σ W_e [1/m]: the electron-rate-weighted mean attenuation, the
        steepest slope of the convex ln G_e (0 when the column is zero)."""
        total = self.W[:, 2].sum()
        return float(self.W[:, 2] @ self.c / total) if total > 0 else 0.0

    @cached_property
    def image_tables(self) -> dict:
        """Image-average sample geometries and tables by lens/port geometry (`_image_geometry`), a small cache."""
        return {}


_WEIGHTS_CACHE: dict = {}
IMAGE_TABLES_PER_WEIGHTS = 32
IMAGE_DIRECT_PATHS = 512


def spectral_weights(d: Design) -> SpectralWeights:
    """The design's spectral weights, cached by its categorical inputs (spectral files, water, sensor)."""
    key = _spectral_key(d)
    if key not in _WEIGHTS_CACHE:
        if len(_WEIGHTS_CACHE) > 64:
            _WEIGHTS_CACHE.clear()
        _WEIGHTS_CACHE[key] = _compute_weights(d)
    return _WEIGHTS_CACHE[key]


def _compute_weights(d: Design) -> SpectralWeights:
    grid = d.grid
    s = radiant_per_lumen(relative_spectrum(d["light.spectrum"], grid), grid)
    iop = water_iop(d["water.type"], grid)
    added = extended.particles(d).b_per_m(grid.nm)
    b_water, b_suspended = scattering_parts(iop.b_per_m, grid.nm)
    c = iop.c_per_m + added
    m = reflectance(d["target.reflectance"], grid)
    t = transmittance(d["lens.transmittance"], grid)
    qe = d.sensor.qe_on(grid, d["sensor.channel"])
    m_spec = m if _is_spectral(d, "target.reflectance") else np.ones_like(grid.nm)
    t_spec = t if _is_spectral(d, "lens.transmittance") else np.ones_like(grid.nm)
    base = s * grid.w_nm
    photons = base * photons_per_joule(grid.nm)
    W = np.stack(
        [
            base,
            base * m_spec * t_spec,
            photons * m_spec * t_spec * qe,
            photons,
            photons * m_spec,
            photons * m_spec * t_spec,
        ],
        axis=1,
    )
    return SpectralWeights(
        c=c,
        W=W,
        s_per_lm=s,
        reflectance=m_spec,
        lens_transmittance=t_spec,
        qe=qe,
        b_water=b_water,
        b_particles=b_suspended + added,
    )


def _is_spectral(d: Design, dotted: str) -> bool:
    """A factor given as a file is spectral (folded into W); a number (or grid array) is broadband."""
    return isinstance(d[dotted], str)


def broadband_factor(d: Design, dotted: str):
    """A broadband factor: the configured number, or 1 when the factor is spectral (already in W)."""
    return 1.0 if _is_spectral(d, dotted) else d[dotted]


def path_integrals(weights: SpectralWeights, path_m) -> np.ndarray:
    """∫ W(λ) exp(−c(λ) D) dλ for attenuating path lengths D (any shape) → shape D.shape + (3,), summed over
    the wavelength grid (the reference the chain's interpolation table, `SpectralWeights.table`, is tested
    against)."""
    path = np.asarray(path_m, float)
    return np.exp(-path[..., None] * weights.c) @ weights.W


def beam_half_angle_rad(d: Design):
    """Beam half-angle in water [rad]; one given in air behind a flat light port is refracted (Snell)."""
    if d["light.beam_half_angle_deg"] is not None:
        return np.radians(d["light.beam_half_angle_deg"])
    return np.arcsin(np.sin(np.radians(d["light.beam_half_angle_in_air_deg"])) / d["housing.water_index"])


def _irradiance_geometry(d: Design, beta, cos_incidence):
    """Target irradiance per unit spectral radiant flux without attenuation [1/m²] (steps 2 of the chain)."""
    count = d["light.count"]
    d_l = light_distance_m(d)
    if paper_beam_model(d) == "cone":
        return count * cos_incidence / (2 * np.pi * (1 - np.cos(beta)) * d_l**2)
    return count / (np.pi * (d_l * np.tan(beta)) ** 2)


def paper_beam_model(d: Design) -> str:
    """The paper chain's beam: "disk", or "cone" (a cos-power beam, an extended-model profile, counts as a cone of
    its half-angle)."""
    return "disk" if d["light.beam_model"] == "disk" else "cone"


def light_distance_m(d: Design):
    """Light → target distance [m]: `light.distance_m`, by default the altitude."""
    value = d["light.distance_m"]
    return d["operation.altitude_m"] if value is None else value


def housing_transmittance(d: Design):
    """The camera port's transmittance: the configured number, or the Fresnel value at normal incidence."""
    value = d["housing.port_transmittance"]
    if isinstance(value, str):
        return port_model.port_transmittance(d["housing.water_index"], d["housing.port_index"])
    return value


def _radiance_to_sensor_factor(d: Design, weights: SpectralWeights):
    """Broadband factors from target irradiance to sensor irradiance: M/π · T_port/n_w² · T_lens · π/(4N²)."""
    m = broadband_factor(d, "target.reflectance")
    t = broadband_factor(d, "lens.transmittance")
    return (
        (m / np.pi)
        * housing_transmittance(d)
        / d["housing.water_index"] ** 2
        * t
        * optics.lens_irradiance_factor(d["lens.f_number"])
    )


def effective_focal_length_m(d: Design):
    """Focal length seen from the water [m]: n_w f behind a flat port, f behind a centred dome."""
    f = d["lens.focal_length_mm"] * 1e-3
    return f * d["housing.water_index"] if d["housing.port"] == "flat" else f * np.ones_like(d["housing.water_index"])


def _field_terms(d: Design, r_m):
    """(angular weight, path secant) of pixels at image radius r_m (trailing axis): cos⁴α_air · [α_w ≤ β] ·
    cos³α_w (cone model; 1 for the disk) and 1/cos α_w, broadcast against the design's arrays."""
    beta = beam_half_angle_rad(d)
    f = np.asarray(d["lens.focal_length_mm"] * 1e-3, float)[..., None]
    tan_air = np.asarray(r_m, float) / f
    tan_w = tan_air / np.asarray(d["housing.water_index"])[..., None] if d["housing.port"] == "flat" else tan_air
    cos_air = 1 / np.sqrt(1 + tan_air**2)
    cos_w = 1 / np.sqrt(1 + tan_w**2)
    in_beam = np.arctan(tan_w) <= np.asarray(beta)[..., None]
    return cos_air**4 * in_beam * (cos_w**3 if paper_beam_model(d) == "cone" else 1.0), 1 / cos_w


def _attenuating_path_m(d: Design):
    """Attenuating path of the on-axis pixel, light → target → camera: scale · (d_L + d_C) [m]."""
    return np.asarray(d["water.attenuation_scale"]) * (np.asarray(light_distance_m(d)) + d["operation.altitude_m"])


def _image_prefactor(d: Design, weights: SpectralWeights):
    """Electron rate per unit (angular weight × spectral integral) of the off-axis pixels: flux, beam
    concentration without incidence, broadband factors to the sensor, pixel area."""
    beta = beam_half_angle_rad(d)
    return (
        d["light.luminous_flux_lm"]
        * _irradiance_geometry(d, beta, 1.0)
        * _radiance_to_sensor_factor(d, weights)
        * d.sensor.pixel_area_m2
    )


def electron_rate_at_radius(d: Design, r_m, weights: SpectralWeights | None = None):
    """Electron rate [e⁻/s] of pixels at image radius r_m (any shape, trailing axis broadcast against the
    design's arrays) under the image-average geometry of the module docstring: light beside the camera,
    target plane perpendicular to the axis at d_C, cos⁴ lens falloff, beam cut-off at α_w > β. Summed over the
    wavelength grid (`path_integrals`): the reference for the image average."""
    weights = spectral_weights(d) if weights is None else weights
    angular, secant = _field_terms(d, r_m)
    path = _attenuating_path_m(d)[..., None] * secant
    return np.asarray(_image_prefactor(d, weights))[..., None] * angular * path_integrals(weights, path)[..., 2]


def image_radii_m(sensor: SensorProfile) -> np.ndarray:
    """Image radii of the image-average samples: a midpoint grid on one sensor quadrant, sorted."""
    n = IMAGE_SAMPLES_PER_AXIS
    u = (np.arange(n) + 0.5) / n
    size_x, size_y = sensor.size_m
    return np.sort(np.hypot.outer(u * size_x / 2, u * size_y / 2).ravel())


@dataclass(frozen=True)
class _ImageGeometry:
    """The image-average samples of one lens/port geometry, sorted by field angle α_w, and the table of
    H_k(D) = Σ_{i<k} cos⁴α_air,i · cos³α_w,i [cone] · G_e(D / cos α_w,i) (`image_table`)."""

    alpha_w: np.ndarray
    table: LogHermiteTable


def _image_geometry(d: Design, weights: SpectralWeights, focal_m: float, water_index: float) -> _ImageGeometry:
    flat = d["housing.port"] == "flat"
    model = paper_beam_model(d)
    key = (id(d.sensor), focal_m, water_index if flat else None, model)
    cache = weights.image_tables
    if key not in cache:
        tan_air = image_radii_m(d.sensor) / focal_m
        tan_w = tan_air / water_index if flat else tan_air
        cos_air = 1 / np.sqrt(1 + tan_air**2)
        cos_w = 1 / np.sqrt(1 + tan_w**2)
        if len(cache) >= IMAGE_TABLES_PER_WEIGHTS:
            del cache[next(iter(cache))]
        angular = cos_air**4 * (cos_w**3 if model == "cone" else 1.0)
        cache[key] = _ImageGeometry(np.arctan(tan_w), image_table(weights.table, 1 / cos_w, angular))
    return cache[key]


def _image_average_rate(d: Design, weights: SpectralWeights):
    """Mean electron rate per pixel over the sensor [e⁻/s]: the mean of `electron_rate_at_radius` over the
    image samples (`image_radii_m`), with the spectral integral from the interpolation table.

    Three routes, by the shape of the grid; all agree with the wavelength sum over every sample to 1e-8
    (tests/sim/test_spectral_table.py).
    - Many path lengths per lens/port geometry (altitude or attenuation axes): each geometry gets a table of the
      cumulative sums over the samples sorted by field angle (`uwlab.model.spectral_table.image_table`); the
      samples inside a beam are a prefix, and a point costs one lookup.
    - Many beam angles per path and geometry: the samples are summed directly, one lookup per sample and path,
      shared by the beams.
    - Otherwise (a single design, or a lens/port geometry per point): a Gauss rule of the sample radii
      (`_image_sum`), 8 to 24 lookups per point."""
    path = _attenuating_path_m(d)
    focal = np.asarray(d["lens.focal_length_mm"] * 1e-3, float)
    water = np.asarray(d["housing.water_index"], float) if d["housing.port"] == "flat" else np.asarray(1.0)
    beta = np.asarray(beam_half_angle_rad(d), float)
    radii = image_radii_m(d.sensor)
    geometries = np.broadcast_shapes(focal.shape, water.shape)
    pairs = int(np.prod(np.broadcast_shapes(path.shape, geometries)))
    points = int(np.prod(np.broadcast_shapes(path.shape, geometries, beta.shape)))
    lit = int(np.prod(np.broadcast_shapes(geometries, beta.shape)))
    if pairs > IMAGE_DIRECT_PATHS * int(np.prod(geometries)):
        total = np.empty(np.broadcast_shapes(beta.shape, path.shape, geometries))
        for index in np.ndindex(geometries):
            where = _mesh_index(index, geometries, total.ndim)
            geometry = _image_geometry(d, weights, _pick(focal, where).item(), _pick(water, where).item())
            in_beam = np.searchsorted(geometry.alpha_w, _pick(beta, where), side="right")
            total[where] = geometry.table.at_columns(_pick(path, where), in_beam)
    elif pairs * radii.size * 2 <= points * IMAGE_RULES[0][0] and max(pairs, lit) * radii.size <= IMAGE_SAMPLES_MAX:
        angular, secant = _field_terms(d, radii)
        total = np.einsum("...i,...i->...", weights.table(path[..., None] * secant, 2), angular)
    else:
        total = _image_sum(d, weights, path, focal, water, beta)
    total *= weights.table.nonzero[2]
    return _image_prefactor(d, weights) * total / radii.size


IMAGE_RULES = ((8, 1.0, 2.0), (12, 2.0, 8.0), (16, 4.0, 8.0), (24, 9.0, 16.0))
"""Gauss rules of the image average, (nodes, largest tan²α_air, largest κ) each, the bounds growing from rule to
rule: a point takes the first rule whose bounds hold for its last sample inside the beam, and otherwise every
sample (`_image_sum`). κ = c̄ D
(sec α_w − 1) bounds the drop of ln G across the field (c̄ = −d ln G/dD at D = 0, the largest slope of the convex
ln G). Within these bounds the rules match the sum over the samples to < 5e-9 relative (Jerlov I–9C and pure
water, f ≥ 1 mm on a 2/3" sensor, paths up to 300 m, flat and dome ports, cone and disk beams; checked in
tests/sim/test_spectral_table.py)."""
IMAGE_PIECE = 1 << 14  # points per pass of `_image_sum` (bounds the (points × nodes) temporaries)
IMAGE_SAMPLES_MAX = 1 << 22  # the largest (points × samples) array of the direct route


@dataclass(frozen=True)
class _RadiusRules:
    """The image samples' distinct radii² x (sorted) with their multiplicities, and, built when first needed, per
    `IMAGE_RULES` entry the Gauss rules of every prefix of Σ_i count_i δ(x − x_i)
    (`uwlab.model.quadrature.prefix_gauss_rules`), each (nodes, weights) of shape (distinct radii + 1, m); the
    entry after the last is the samples themselves (exact)."""

    radius_m: np.ndarray
    x_m2: np.ndarray
    counts: np.ndarray
    built: dict = field(default_factory=dict)

    def rule(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        if index not in self.built:
            if index < len(IMAGE_RULES):
                self.built[index] = quadrature.prefix_gauss_rules(self.x_m2, self.counts, IMAGE_RULES[index][0])
            else:
                prefix = np.arange(self.x_m2.size)[None, :] < np.arange(self.x_m2.size + 1)[:, None]
                self.built[index] = (np.broadcast_to(self.x_m2, prefix.shape), self.counts * prefix)
        return self.built[index]


_RULES_CACHE: dict = {}


def _radius_rules(sensor: SensorProfile) -> _RadiusRules:
    key = sensor.size_m
    if key not in _RULES_CACHE:
        x, counts = np.unique(image_radii_m(sensor) ** 2, return_counts=True)
        _RULES_CACHE[key] = _RadiusRules(np.sqrt(x), x, counts.astype(float))
    return _RULES_CACHE[key]


def _image_sum(d: Design, weights: SpectralWeights, path, focal, water, beta) -> np.ndarray:
    """Σ_i cos⁴α_air,i · [α_w,i ≤ β] · cos³α_w,i [cone] · G_e(D / cos α_w,i) over the image samples
    (`image_radii_m`), for path D, focal length f [m], n_w (1 for a dome) and beam β, all broadcast.

    Per point, the samples inside the beam are the p smallest distinct radii (tan α_w = r / (f n_w) ≤ tan β), and
    the summand is a smooth function of x = r²; their sum is taken by the Gauss rule of the discrete measure of
    those radii² (`_radius_rules`, `IMAGE_RULES`: 8 to 24 nodes, a table lookup each), or over every sample
    where the field is too wide or the attenuation across it too steep for the rules' bounds."""
    rules = _radius_rules(d.sensor)
    cone = paper_beam_model(d) == "cone"
    shape = np.broadcast_shapes(path.shape, focal.shape, water.shape, beta.shape)
    prefix = np.searchsorted(rules.radius_m, focal * water * np.tan(beta), side="right")
    x_last = rules.x_m2[np.maximum(prefix, 1) - 1]
    tan2_air = x_last / focal**2
    kappa = weights.electron_mean_rate_per_m * path * (np.sqrt(1 + tan2_air / water**2) - 1)
    choice = sum(~((tan2_air <= tan2_max) & (kappa <= kappa_max)) for _, tan2_max, kappa_max in IMAGE_RULES)
    path, f2, n2, prefix, choice = (
        np.broadcast_to(v, shape).ravel() for v in (path, focal**2, water**2, prefix, choice)
    )
    total = np.empty(choice.size)
    used = np.unique(choice)
    for r in used:
        members = np.arange(choice.size) if used.size == 1 else np.flatnonzero(choice == r)
        nodes, node_weights = rules.rule(int(r))
        piece = max(1, IMAGE_PIECE * 8 // nodes.shape[1])
        for s in range(0, members.size, piece):
            at = members[s : s + piece]
            p = prefix[at]
            f2n2 = (f2[at] * n2[at])[:, None]
            x = nodes[p]
            cos2_w = f2n2 / (f2n2 + x)
            sec_w = 1 / np.sqrt(cos2_w)
            term = node_weights[p] * (f2[at][:, None] / (f2[at][:, None] + x)) ** 2
            if cone:
                term *= cos2_w / sec_w
            term *= weights.table(path[at][:, None] * sec_w, 2)
            total[at] = term.sum(axis=-1)
    return total.reshape(shape)


def _mesh_index(index: tuple, axes: tuple, ndim: int) -> tuple:
    """An index of the full grid (`ndim` axes) selecting point `index` of the `axes` shape (right-aligned):
    length-1 slices on the axes longer than 1, whole axes elsewhere."""
    pad = ndim - len(index)
    return (slice(None),) * pad + tuple(
        slice(i, i + 1) if n > 1 else slice(None) for i, n in zip(index, axes, strict=True)
    )


def _pick(array: np.ndarray, where: tuple) -> np.ndarray:
    """`array` at the mesh index `where`, along the axes where the array is not broadcast (length > 1)."""
    if array.ndim == 0:
        return array
    where = where[len(where) - array.ndim :]
    return array[tuple(w if n > 1 else slice(None) for w, n in zip(where, array.shape, strict=True))]


def _on_axis(d: Design, weights: SpectralWeights):
    """(target irradiance [W/m²], sensor irradiance [W/m²], electron rate [e⁻/s]) on the optical axis."""
    beta = beam_half_angle_rad(d)
    geometry = d["light.luminous_flux_lm"] * _irradiance_geometry(d, beta, np.cos(np.radians(d["light.incidence_deg"])))
    scale = np.asarray(d["water.attenuation_scale"])
    d_l = np.asarray(light_distance_m(d))
    target = geometry * weights.table(scale * d_l, 0)
    to_sensor = geometry * _radiance_to_sensor_factor(d, weights)
    path = scale * (d_l + d["operation.altitude_m"])
    return target, to_sensor * weights.table(path, 1), to_sensor * weights.table(path, 2) * d.sensor.pixel_area_m2


def _extended_on_axis(d: Design, weights: SpectralWeights):
    """The extended chain's (target irradiance at the target's centre [W/m²], sensor irradiance [W/m²], target
    electron rate, veiling-light electron rate [e⁻/s]) of the on-axis pixel (of the bare sensor)."""
    chain = extended.Chain(d, weights)
    port = housing_transmittance(d)
    if extended.is_bare(d):
        direct, veil = chain.bare_rates(port)
        irradiance = sum(chain.bare_rates(port, watts=True))
    else:
        lens = broadband_factor(d, "lens.transmittance")
        centre = (np.zeros(1), np.zeros(1), port, lens)
        direct, veil = (x[..., 0] for x in chain.pixel_rates(*centre))
        irradiance = sum(chain.pixel_rates(*centre, watts=True))[..., 0]
    return chain.target_irradiance(weights), irradiance, direct, veil


def on_axis_electron_rate(d: Design):
    """Electron rate [e⁻/s] of the on-axis pixel (extended: target and veiling light; the bare sensor's mean),
    before any clipping (μ_e = rate · t_exp)."""
    weights = spectral_weights(d)
    if d["model.kind"] == "extended":
        _, _, direct, veil = _extended_on_axis(d, weights)
        return direct + veil
    return _on_axis(d, weights)[2]


def extended_image_rates(d: Design, weights: SpectralWeights | None = None):
    """(target, veiling light) mean electron rates per pixel [e⁻/s] over the sensor in the extended chain (a
    16 × 16 midpoint grid over the whole frame; the bare sensor is uniform)."""
    weights = spectral_weights(d) if weights is None else weights
    chain = extended.Chain(d, weights)
    port = housing_transmittance(d)
    if extended.is_bare(d):
        return chain.bare_rates(port)
    x, y = chain.image_positions()
    direct, veil = chain.pixel_rates(x, y, port, broadband_factor(d, "lens.transmittance"))
    return direct.mean(axis=-1), veil.mean(axis=-1)


def paper(d: Design) -> Design:
    """The design under the paper's chain ([model] kind = "paper"): every extended-model key is then ignored."""
    return d.with_values(**{"model.kind": "paper"})


def circle_of_confusion_m(d: Design):
    """The acceptable circle of confusion on the sensor [m]: `operation.circle_of_confusion_mm`, by default the
    sensor diagonal / 1500."""
    coc = d["operation.circle_of_confusion_mm"]
    return d.sensor.diagonal_m / 1500 if coc is None else np.asarray(coc) * 1e-3


def port_geometry(d: Design):
    """(port, n_w, flat, dome, decenter_z_m) for the paraxial formulas of `uwlab.model.optics` and
    `uwlab.model.focus`: flat = (air_gap_m, thickness_m, port_index); dome = (radius_m, thickness_m, port_index)
    or None for a flat port; decenter_z_m the pupil's axial offset from the dome's centre."""
    h = d.values["housing"]
    flat = (h["flat_air_gap_mm"] * 1e-3, h["flat_thickness_mm"] * 1e-3, h["port_index"])
    dome = None
    if h["port"] == "dome":
        dome = (h["dome_radius_mm"] * 1e-3, h["dome_thickness_mm"] * 1e-3, h["port_index"])
    return h["port"], h["water_index"], flat, dome, h["dome_decenter_mm"][2] * 1e-3


def evaluate(d: Design) -> dict[str, np.ndarray]:
    """All design outputs (the keys of `uwlab design --json`) as arrays broadcast over the design's grid axes."""
    weights = spectral_weights(d)
    sensor = d.sensor
    op = d.values["operation"]
    f_eff = effective_focal_length_m(d)
    size = dict(zip("xy", sensor.size_m, strict=True))
    res = dict(zip("xy", sensor.resolution_px, strict=True))
    fov = {a: optics.angular_fov_rad(size[a], f_eff) for a in "xy"}
    d_c = op["altitude_m"]
    fov_m = {a: optics.spatial_fov_m(fov[a], d_c) for a in "xy"}
    axis = op["motion_axis"]
    speed = np.asarray(op["speed_m_s"], float)
    with np.errstate(divide="ignore"):
        max_exposure = np.where(speed > 0, op["max_blur_px"] * fov_m[axis] / (speed * res[axis]), np.inf)
    min_framerate = speed / (fov_m[axis] * (1 - np.asarray(op["overlap"])))
    if isinstance(op["exposure_s"], str):
        exposure = np.clip(max_exposure, sensor.exposure_min_us * 1e-6, sensor.exposure_max_us * 1e-6)
    else:
        exposure = np.asarray(op["exposure_s"], float)

    coc_m = circle_of_confusion_m(d)
    f_m = d["lens.focal_length_mm"] * 1e-3
    port, n_w, flat, dome, decenter_z = port_geometry(d)
    near, far = optics.dof_underwater(d_c, f_m, d["lens.f_number"], coc_m, port, n_w, dome, flat)
    min_n = None
    if op["min_dof_m"] is not None:
        min_n = optics.min_f_number(d_c, f_m, coc_m, op["min_dof_m"], port, n_w, dome, flat=flat)
    virtual = port_model.dome_virtual_distance(d_c, *dome[:2], n_w, dome[2]) if dome else None
    focus_image = focus.target_image_distance_m(d_c, port, n_w, flat, dome, decenter_z)
    min_focus = d["lens.min_focus_distance_m"]
    close_up = focus.close_up_lens_dpt(focus_image, min_focus) if min_focus is not None else None

    bits = d["sensor.bit_depth"]
    k = sensor.gain_k(d["sensor.gain_db"], bits)
    dark = sensor.dark_dn(bits)
    extras = {}
    if d["model.kind"] == "extended":
        target, sensor_irradiance, rate, veil = _extended_on_axis(d, weights)
        mu_e, mu_y, saturated, snr_value, veil_e = _extended_response(rate, veil, exposure, k, dark, bits, sensor)
        image_rate, image_veil = extended_image_rates(d, weights)
        image_e, image_y, _, image_snr, image_veil_e = _extended_response(
            image_rate, image_veil, exposure, k, dark, bits, sensor
        )
        extras = {"veil_electrons": veil_e}
        image_extras = {"veil_electrons": image_veil_e}
    else:
        target, sensor_irradiance, rate = _on_axis(d, weights)
        mu_e_raw = rate * exposure
        mu_y, saturated = response_dn(mu_e_raw, k, dark, sensor.saturation_e, bits)
        mu_e = np.minimum(mu_e_raw, sensor.saturation_e)
        snr_value = snr(mu_e, sensor.dark_noise_e, k)
        image_raw = _image_average_rate(d, weights) * exposure
        image_y, _ = response_dn(image_raw, k, dark, sensor.saturation_e, bits)
        image_e = np.minimum(image_raw, sensor.saturation_e)
        image_snr = snr(image_e, sensor.dark_noise_e, k)
        image_extras = {}
    with np.errstate(divide="ignore"):
        snr_db = 20 * np.log10(snr_value)
    return {
        "effective_focal_length_mm": f_eff * 1e3,
        "fov_deg": {a: np.degrees(fov[a]) for a in "xy"},
        "fov_m": fov_m,
        "max_exposure_s": max_exposure,
        "exposure_s": exposure,
        "min_framerate_hz": min_framerate,
        "dof_m": {"near": near, "far": far},
        "min_f_number_for_dof": min_n,
        "dome_virtual_image_m": virtual,
        "focus_image_m": focus_image,
        "focus_setting_m": focus.focus_setting_m(focus_image, min_focus),
        "close_up_lens_dpt": close_up,
        "target_irradiance_w_m2": target,
        "sensor_irradiance_w_m2": sensor_irradiance,
        "mean_electrons": mu_e,
        "mean_dn": mu_y,
        "mean_fraction": mu_y / (2.0 ** np.asarray(bits) - 1),
        "saturated": saturated,
        "snr": snr_value,
        "snr_db": snr_db,
        **extras,
        "image_average": {"mean_electrons": image_e, "mean_dn": image_y, "snr": image_snr, **image_extras},
        "light_budget_stops": light_budget(d, weights, fov_m),
    }


def _extended_response(rate, veil, exposure, k, dark, bits, sensor):
    """(μ_e, μ_y, saturated, SNR, μ_veil) of a pixel receiving target and veiling light: the camera records both;
    the SNR is the target's signal over the shot noise of both (`uwlab.model.sensor.snr`). At saturation both are
    clipped in proportion."""
    total_raw = (rate + veil) * exposure
    mu_y, saturated = response_dn(total_raw, k, dark, sensor.saturation_e, bits)
    total = np.minimum(total_raw, sensor.saturation_e)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(total_raw > 0, veil * exposure / total_raw, 0.0)
    veil_e = total * share
    return total, mu_y, saturated, snr(total - veil_e, sensor.dark_noise_e, k, veil_e), veil_e


SPECTROMETER_POSITIONS = ("target", "camera", "sensor")
"""Where a rig's spectrometer reads the chain: ``target``, the irradiance on a board facing the light;
``camera``, π L_w at the camera (the irradiance from the Lambertian target filling the meter's field); ``sensor``,
the irradiance on the sensor plane (on an EMVA 1288 bench, `uwlab.model.bench`, where the standard's photodiode sits,
Release 4.0 Linear §6.4)."""


LIGHT_BUDGET_STAGES = (
    "beam_to_view",
    "water_to_target",
    "reflectance",
    "water_to_camera",
    "port",
    "aperture",
    "lens_transmittance",
    "quantum_efficiency",
)


def light_budget(d: Design, weights: SpectralWeights, fov_m: dict) -> dict[str, np.ndarray]:
    """Light lost at each stage of the on-axis chain, in stops (−log₂ of the fraction passed on).

    The fractions multiply to R / Q: R the electron rate of the whole sensor at the on-axis rate (rate × pixels),
    Q the photon rate emitted by the lights. Stages: the beam's on-axis irradiance × the imaged footprint / the
    flux (negative when a beam narrower than the view concentrates more than the footprint's share); water on
    the light path and on the return path, the reflectance and the lens transmittance, each weighted by the
    photon spectrum reaching it; the port, T_port/n_w² · (f_eff/f)² (flat: T_port; the n_w² of the radiance is
    won back by the longer focal length); the aperture, the share of the target's Lambertian radiance entering
    the pupil, f²/(4 N² d_C²); the quantum efficiency, electrons per photon reaching the sensor.
    """
    scale = np.asarray(d["water.attenuation_scale"])
    d_l = np.asarray(light_distance_m(d))
    d_c = np.asarray(d["operation.altitude_m"])
    near, far = scale * d_l, scale * (d_l + d_c)
    table = weights.table
    source = table(np.zeros(1), 3)[0]
    lit, reflected = table(near, 3), table(near, 4)
    returned, transmitted = table(far, 4), table(far, 5)
    beta = beam_half_angle_rad(d)
    beam = (
        _irradiance_geometry(d, beta, np.cos(np.radians(d["light.incidence_deg"])))
        / d["light.count"]
        * fov_m["x"]
        * fov_m["y"]
    )
    focal = d["lens.focal_length_mm"] * 1e-3
    fractions = {
        "beam_to_view": beam,
        "water_to_target": lit / source,
        "reflectance": reflected / lit * broadband_factor(d, "target.reflectance"),
        "water_to_camera": returned / reflected,
        "port": housing_transmittance(d) / d["housing.water_index"] ** 2 * (effective_focal_length_m(d) / focal) ** 2,
        "aperture": focal**2 / (4 * np.asarray(d["lens.f_number"]) ** 2 * d_c**2),
        "lens_transmittance": transmitted / returned * broadband_factor(d, "lens.transmittance"),
        "quantum_efficiency": table(far, 2) / transmitted,
    }
    with np.errstate(divide="ignore", invalid="ignore"):
        return {k: -np.log2(np.asarray(v, float)) for k, v in fractions.items()}


def stage_spectra(d: Design) -> dict[str, np.ndarray]:
    """Spectra along the on-axis chain for a scalar design (for plots and the simulated spectrometer).

    Keys: wavelength_nm; source_w_nm (Φe, all lights); target_irradiance_w_m2_nm (E_t); facing_light_w_m2_nm (the
    irradiance on a board at the target's centre facing the light, E_t / cos θ_i; extended: of every light, on a
    surface across its ray); return_radiance_w_m2_sr_nm (L_w at the camera, before the port; extended: with the
    veiling light); sensor_irradiance_w_m2_nm (E_s); absorbed_w_m2_nm (E_s η).
    """
    if d["model.kind"] == "extended":
        return _extended_spectra(d)
    w = spectral_weights(d)
    grid = d.grid
    c = w.c * d["water.attenuation_scale"]
    beta = beam_half_angle_rad(d)
    flux = d["light.luminous_flux_lm"]
    source = d["light.count"] * flux * w.s_per_lm
    geometry = flux * _irradiance_geometry(d, beta, np.cos(np.radians(d["light.incidence_deg"])))
    d_l, d_c = light_distance_m(d), d["operation.altitude_m"]
    e_t = geometry * w.s_per_lm * np.exp(-c * d_l)
    l_w = e_t * w.reflectance * broadband_factor(d, "target.reflectance") / np.pi * np.exp(-c * d_c)
    e_s = (
        l_w
        * housing_transmittance(d)
        / d["housing.water_index"] ** 2
        * w.lens_transmittance
        * broadband_factor(d, "lens.transmittance")
        * optics.lens_irradiance_factor(d["lens.f_number"])
    )
    return {
        "wavelength_nm": grid.nm,
        "source_w_nm": source,
        "target_irradiance_w_m2_nm": e_t,
        "facing_light_w_m2_nm": e_t / np.cos(np.radians(d["light.incidence_deg"])),
        "return_radiance_w_m2_sr_nm": l_w,
        "sensor_irradiance_w_m2_nm": e_s,
        "absorbed_w_m2_nm": e_s * w.qe,
    }


def _extended_spectra(d: Design) -> dict[str, np.ndarray]:
    """`stage_spectra` of the extended chain: at the target's centre and along the on-axis ray (per wavelength)."""
    w = spectral_weights(d)
    chain = extended.Chain(d, w)
    target, facing, radiance = chain.spectra(w)
    lens = broadband_factor(d, "lens.transmittance") * w.lens_transmittance
    e_s = (
        radiance
        * housing_transmittance(d)
        / d["housing.water_index"] ** 2
        * lens
        * optics.lens_irradiance_factor(d["lens.f_number"])
    )
    flux = sum(np.asarray(light.flux_lm) * np.asarray(light.count) for light in chain.lights)
    return {
        "wavelength_nm": d.grid.nm,
        "source_w_nm": flux * w.s_per_lm,
        "target_irradiance_w_m2_nm": target,
        "facing_light_w_m2_nm": facing,
        "return_radiance_w_m2_sr_nm": radiance,
        "sensor_irradiance_w_m2_nm": e_s,
        "absorbed_w_m2_nm": e_s * w.qe,
    }
