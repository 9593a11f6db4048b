"""The extended image-formation chain ([model] kind = "extended"): placed lights, beam profiles, the target pixel by
pixel, veiling light and vignetting. With [model] kind = "paper" none of this runs and `uwlab.model.chain` is the
paper's chain unchanged.

Conventions: the camera frame has its origin where the optical axis leaves the port into the water (where the
paper's thin flat port puts the entrance pupil), x right, y down, z along the optical axis; the water fills z ≥ 0,
the target is the plane z = d_C (the altitude), facing the camera. Lengths in metres, angles in radians; design
numbers may be arrays (grid axes; the port's keys must be single values, its rays are traced), sample axes last.

Lights (`lights`): the [[lights]] array (position, aim point, flux, beam, the transmittance of anything between
the light and the water; a light behind the port, z < 0, shines through air until the water begins at z = 0),
else ``count`` lights `light.separation_m`
from the axis in the camera's plane, evenly spread from above the camera (−y), aimed at the target's centre or
along the axis (`light.aim`), else the paper's geometry: ``count`` lights at `light.distance_m` from the target's
centre with incidence `light.incidence_deg`, in the y–z plane above the axis, aimed at the centre. Every light is a
point source with intensity I(ψ) = Φ κ(ψ) [W/sr per W], ψ from its aim:

- ``cone``: κ = 1/(2π(1 − cos β)) for ψ ≤ β (the paper's uniform cone); ``disk``: κ = 1/(π tan²β) for ψ ≤ β (the
  original tool's disk, whose on-axis irradiance is Φ/(π(d tan β)²)); ``cos-power``: κ = (m+1)/(2π) cos^m ψ with
  m = −ln 2 / ln cos β, a generalised Lambertian beam at half intensity at β (Moreno & Sun, "Modeling the radiation
  pattern of LEDs", Optics Express 16(3), 1808–1819, 2008).
- A beam given in air (`beam_half_angle_in_air_deg`) belongs to a light behind a flat port facing its aim: the
  profile holds in air and the intensity in water follows from étendue conservation through the port,
  κ_w(ψ_w) = κ_a(ψ_a) n_w² cos ψ_w / cos ψ_a with sin ψ_a = n_w sin ψ_w (Snell), which conserves the flux (the
  paper model instead uses the same profile with the refracted half-angle; the two differ by a few per cent).

Irradiance of a target point X from a light at P: E = Φ κ(ψ) cos i / r² · e^(−c r), r = |X − P|, cos i = (X − P)_z / r
(a light behind the target plane gives nothing). A pixel at image position (u, v) looks along tan α_air = (u, v)/f,
traced exactly through the port (`uwlab.model.raytrace`: a flat window with its air gap and thickness, or a dome),
and sees the point X where its ray in the water meets the target plane: the board (`target.board_size_m`,
centred; reflectance M) or its surround (`target.surround_reflectance`); without a board the target fills the
view. Its direct electron rate is
A ∫ M/π E(λ) e^(−c d_C / cos α_w) T_port/n_w² · T_lens π/(4N²) cos⁴α_air V(r) η λ/(hc) dλ, the paper's chain per
pixel; V(r) = 1 − v (r / r_corner)⁴ is the mechanical vignetting (v = `lens.mechanical_vignetting`).

Veiling light (single scattering, the backscatter component of McGlamery, Proc. SPIE 208, 1979 and Jaffe, IEEE J.
Oceanic Eng. 15(2), 101–111, 1990): the path radiance along the pixel's ray up to the target,
L_b = ∫₀^(d_C / cos α_w) Σ_lights β(θ) Φ κ(ψ)/r² e^(−c (r + s)) ds with β = b_w p̃_w(θ) + b_p p̃_p(θ)
(`uwlab.model.scattering`; the attenuation scale multiplies b as it does c), θ the angle between the light's ray
and the direction back to the camera; Gauss–Legendre quadrature in s. It reaches the sensor like the target's
radiance and adds its shot noise: SNR = μ_target / √(σ_d² + σ_q²/K² + μ_target + μ_veil).

The bare sensor (f-number 1/2, `uwlab.model.optics.NO_LENS`) integrates the radiance over its hemisphere,
E = π ⟨L_air⟩ over a grid uniform in sin²θ_air and azimuth, its rays traced through the port like the pixels'.

Spectral integrals ∫ w(λ) e^(−c(λ) D) dλ come from the chain's table over the attenuating path length D
(`uwlab.model.spectral_table.SpectralTable`, 1e-9 of the wavelength sum).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from uwlab.errors import ConfigError
from uwlab.model import optics
from uwlab.model.raytrace import port_from_housing
from uwlab.model.photometry import photons_per_joule
from uwlab.model.scattering import ParticleScattering, pure_water_phase
from uwlab.model.spectral_table import SpectralTable

SCATTER_NODES = 24
IMAGE_SAMPLES_PER_AXIS = 16
HEMISPHERE_SAMPLES = (32, 48)
BARE_F_NUMBER = optics.BARE_SENSOR_F_NUMBER
COLUMNS = ("e_direct", "e_water", "e_particles", "w_direct", "w_water", "w_particles")


def _deg(x):
    return np.radians(np.asarray(x, float))


@dataclass(frozen=True)
class Beam:
    """A light's beam: profile ``model`` ("cone", "disk", "cos-power"), half-angle [rad] (array or number) and
    whether it is given in air (behind a flat port)."""

    model: str
    half_angle: object
    in_air: bool

    def kappa(self, cos_psi, water_index):
        """κ(ψ) = I(ψ)/Φ [1/sr] in water at cos ψ (module docstring)."""
        cos_psi = np.clip(np.asarray(cos_psi, float), -1.0, 1.0)
        if not self.in_air:
            return self._profile(cos_psi)
        n = np.asarray(water_index, float)
        sin_air = n * np.sqrt(np.clip(1 - cos_psi**2, 0.0, None))
        inside = (sin_air < 1) & (cos_psi > 0)
        cos_air = np.sqrt(np.clip(1 - sin_air**2, 1e-300, None))
        return np.where(inside, self._profile(cos_air) * n**2 * cos_psi / cos_air, 0.0)

    def _profile(self, cos_psi):
        beta = np.asarray(self.half_angle, float)
        if self.model == "cos-power":
            m = -np.log(2.0) / np.log(np.cos(beta))
            return (m + 1) / (2 * np.pi) * np.clip(cos_psi, 0.0, None) ** m
        inside = cos_psi >= np.cos(beta)
        if self.model == "cone":
            return np.where(inside, 1.0 / (2 * np.pi * (1 - np.cos(beta))), 0.0)
        return np.where(inside, 1.0 / (np.pi * np.tan(beta) ** 2), 0.0)


@dataclass(frozen=True)
class PlacedLight:
    """One light (or ``count`` coincident ones): position and unit aim, arrays of shape grid + (3,), flux [lm]."""

    position: np.ndarray
    aim: np.ndarray
    flux_lm: object
    beam: Beam
    count: object = 1


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _beam(d, table: dict | None = None) -> Beam:
    table = table or {}
    model = table.get("beam_model") or d["light.beam_model"]
    if table.get("beam_half_angle_deg") is not None:
        return Beam(model, _deg(table["beam_half_angle_deg"]), False)
    if table.get("beam_half_angle_in_air_deg") is not None:
        return Beam(model, _deg(table["beam_half_angle_in_air_deg"]), True)
    if d["light.beam_half_angle_deg"] is not None:
        return Beam(model, _deg(d["light.beam_half_angle_deg"]), False)
    return Beam(model, _deg(d["light.beam_half_angle_in_air_deg"]), True)


def check_off_axis(d, placed: list[PlacedLight]) -> None:
    """Refuse a light on the optical axis in scattering water (0 ≤ z < d_C): the central pixel would look into a
    point source and receive unbounded veiling light."""
    altitude = np.asarray(d["operation.altitude_m"], float)
    for index, light in enumerate(placed):
        position = np.asarray(light.position, float)
        on_axis = (
            (np.hypot(position[..., 0], position[..., 1]) < 1e-9)
            & (position[..., 2] >= 0)
            & (position[..., 2] < altitude)
        )
        if np.any(on_axis):
            key = (
                f"lights[{index}].position_m"
                if d.values.get("lights")
                else "light.separation_m"
                if d["light.separation_m"] is not None
                else "light.distance_m"
            )
            raise ConfigError(
                key,
                np.asarray(position).tolist(),
                "puts a light on the camera's axis in scattering "
                "water; the extended model needs the lights beside it ([[lights]] or light.separation_m)",
            )


def lights(d) -> list[PlacedLight]:
    altitude = np.asarray(d["operation.altitude_m"], float)
    centre = np.stack(np.broadcast_arrays(0.0 * altitude, 0.0 * altitude, altitude), axis=-1)
    if d.values.get("lights"):
        out = []
        for index, table in enumerate(d.values["lights"]):
            position = np.asarray(table["position_m"], float)
            aim = np.asarray(table["aim_m"], float) - position if table["aim_m"] is not None else np.array([0, 0, 1.0])
            if np.linalg.norm(aim) == 0:
                raise ConfigError(f"lights[{index}].aim_m", table["aim_m"], "must differ from position_m")
            flux = table["luminous_flux_lm"] if table["luminous_flux_lm"] is not None else d["light.luminous_flux_lm"]
            out.append(PlacedLight(position, _unit(aim), np.asarray(flux) * table["transmittance"], _beam(d, table)))
        return out
    beam = _beam(d)
    flux = d["light.luminous_flux_lm"]
    if d["light.separation_m"] is not None:
        count = d["light.count"]
        if np.ndim(count):
            raise ConfigError("light.count", np.asarray(count).tolist(), "cannot be varied with light.separation_m")
        separation = np.asarray(d["light.separation_m"], float)
        out = []
        for k in range(int(count)):
            angle = -np.pi / 2 + 2 * np.pi * k / int(count)
            position = np.stack(
                np.broadcast_arrays(separation * np.cos(angle), separation * np.sin(angle), 0.0 * separation), axis=-1
            )
            aim = _unit(centre - position) if d["light.aim"] == "target" else np.array([0, 0, 1.0])
            out.append(PlacedLight(position, aim, flux, beam))
        return out
    distance = np.asarray(d["light.distance_m"] if d["light.distance_m"] is not None else altitude, float)
    incidence = _deg(d["light.incidence_deg"])
    offset = distance * np.sin(incidence)
    position = np.stack(np.broadcast_arrays(0.0 * offset, -offset, altitude - distance * np.cos(incidence)), axis=-1)
    return [PlacedLight(position, _unit(centre - position), flux, beam, d["light.count"])]


@dataclass(frozen=True)
class ChainWeights:
    """The extended chain's spectral weights (`COLUMNS`): electron rate (e_*) and sensor irradiance (w_*) per unit
    luminous flux of the direct light (with the spectral reflectance) and of the light scattered by water and by
    particles (× b_w(λ), × b_p(λ), no reflectance); trapezoidal weights applied."""

    c: np.ndarray
    W: np.ndarray

    @cached_property
    def table(self) -> SpectralTable:
        return SpectralTable(self.c, self.W)


def chain_weights(d, weights) -> ChainWeights:
    """`ChainWeights` of a design from its `uwlab.model.weights.SpectralWeights`."""
    grid = d.grid
    to_sensor = weights.s_per_lm * grid.w_nm * weights.lens_transmittance
    electrons = to_sensor * weights.qe * photons_per_joule(grid.nm)
    m = weights.reflectance
    W = np.stack(
        [
            electrons * m,
            electrons * weights.b_water,
            electrons * weights.b_particles,
            to_sensor * m,
            to_sensor * weights.b_water,
            to_sensor * weights.b_particles,
        ],
        axis=1,
    )
    return ChainWeights(weights.c, W)


def particles(d) -> ParticleScattering:
    """The design's suspended particles."""
    return ParticleScattering(
        d["water.particle_scattering_per_m"],
        d["water.particle_scattering_exponent"],
        d["water.particle_phase_function"],
    )


def _g(x):
    """A design array with a sample axis appended."""
    return np.asarray(x, float)[..., None]


class Chain:
    """The extended chain of one design (scalar or grid): per-ray radiances, pixels, the bare sensor, averages."""

    def __init__(self, d, weights):
        self.d = d
        self.spectral = chain_weights(d, weights)
        self.lights = lights(d)
        self.scale = np.asarray(d["water.attenuation_scale"], float)
        self.altitude = np.asarray(d["operation.altitude_m"], float)
        self.n_w = np.asarray(d["housing.water_index"], float)
        self.phase = particles(d)
        self.particles_scatter = bool(np.any(weights.b_particles > 0))
        if np.max(self.scale) > 0 and (np.any(weights.b_water > 0) or self.particles_scatter):
            check_off_axis(d, self.lights)
        value = d["target.reflectance"]
        self.m_broadband = float(np.mean(weights.reflectance)) if isinstance(value, str) else value

    # ------------------------------------------------------------------ light at points
    def _light_terms(self, points):
        """Per light: (Φ κ / r² per lumen of rated flux, unit direction from the light, the water path) at points
        (..., 3). The water fills z ≥ 0; a light behind the port (z < 0) shines through air (or the window) until
        it reaches z = 0, so only the part of its ray at z ≥ 0 attenuates."""
        out = []
        for light in self.lights:
            v = points - light.position[..., None, :] if np.ndim(light.position) > 1 else points - light.position
            r = np.linalg.norm(v, axis=-1)
            r = np.maximum(r, 1e-6)
            direction = v / r[..., None]
            aim = light.aim[..., None, :] if np.ndim(light.aim) > 1 else light.aim
            cos_psi = np.sum(direction * aim, axis=-1)
            half = light.beam.half_angle
            beam = Beam(light.beam.model, _g(half) if np.ndim(half) else half, light.beam.in_air)
            kappa = beam.kappa(cos_psi, _g(self.n_w))
            z_light = light.position[..., None, 2] if np.ndim(light.position) > 1 else light.position[2]
            depth = points[..., 2] - z_light
            with np.errstate(invalid="ignore", divide="ignore"):
                wet = np.where(depth > 0, (points[..., 2] - np.maximum(z_light, 0.0)) / depth, 1.0)
            out.append((_g(light.flux_lm) * _g(light.count) * kappa / r**2, direction, r * np.clip(wet, 0.0, 1.0)))
        return out

    # ------------------------------------------------------------------ rays
    def rays_from_air(self, air) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rays leaving the camera with unit directions `air` (..., n, 3) in air, traced exactly through the port
        (`uwlab.model.raytrace`, with its air gap, thickness, tilt or decentring): (entry points in water, in the
        chain's frame whose origin is where the optical axis enters the water; unit directions in water; lengths
        to the target plane). A ray that does not get out carries no light (zero length)."""
        port = port_from_housing(self.d.values["housing"])
        rays = port.trace(np.asarray(air, float))
        axis = port.trace(np.array([0.0, 0.0, 1.0])).points
        origin = np.where(rays.valid[..., None], rays.points - axis, 0.0)
        direction = np.where(rays.valid[..., None], rays.directions, np.array([0.0, 0.0, 1.0]))
        length = np.where(rays.valid, (_g(self.altitude) - origin[..., 2]) / direction[..., 2], 0.0)
        return origin, direction, np.maximum(length, 0.0)

    def radiance(self, origin, direction, length, watts: bool = False):
        """(target, veil) water radiance along rays per unit rated luminous flux, shape (..., n): in electron-rate
        units (× A_pixel T_port/n_w² T_lens π/(4N²) cos⁴α V gives a pixel's rate [e⁻/s]), or with `watts` in
        W/m²/sr as it reaches the sensor (spectral lens transmittance applied)."""
        first = 3 if watts else 0
        table = self.spectral.table
        scale = _g(self.scale)
        points = origin + direction * length[..., None]
        direct = 0.0
        for term, to_point, r in self._light_terms(points):
            cos_i = np.clip(to_point[..., 2], 0.0, None)
            direct = direct + term * cos_i * table(scale * (r + length), first)
        direct = direct * self._reflectance_factor(points) / np.pi
        veil = self._veil(origin, direction, length, first)
        return direct, veil

    def _reflectance_factor(self, points):
        """M (broadband, or 1 when spectral and folded into the weights) on the board, the surround elsewhere."""
        value = self.d["target.reflectance"]
        m = 1.0 if isinstance(value, str) else _g(value)
        size = self.d["target.board_size_m"]
        if size is None:
            return m
        on_board = (np.abs(points[..., 0]) <= size[0] / 2) & (np.abs(points[..., 1]) <= size[1] / 2)
        surround = self.d["target.surround_reflectance"] / np.maximum(_g(self.m_broadband), 1e-12) * m
        return np.where(on_board, m, surround)

    def _veil(self, origin, direction, length, first):
        """Single-scattering path radiance along rays (module docstring), Gauss–Legendre in s."""
        x, w = np.polynomial.legendre.leggauss(SCATTER_NODES)
        s = 0.5 * length[..., None] * (x + 1)
        weight = 0.5 * length[..., None] * w
        points = origin[..., None, :] + direction[..., None, :] * s[..., None]
        table = self.spectral.table
        scale = _g(_g(self.scale))
        total = 0.0
        nodes = points.shape[-3:-1]
        for term, to_point, r in self._light_terms(points.reshape(*points.shape[:-3], -1, 3)):
            term, r = term.reshape(term.shape[:-1] + nodes), r.reshape(r.shape[:-1] + nodes)
            to_point = to_point.reshape(to_point.shape[:-2] + nodes + (3,))
            cos_theta = -np.sum(to_point * direction[..., None, :], axis=-1)
            path = scale * (r + s)
            scatter = pure_water_phase(cos_theta) * table(path, first + 1)
            if self.particles_scatter:
                scatter = scatter + self.phase.phase_function(cos_theta) * table(path, first + 2)
            total = total + np.sum(weight * term * scatter, axis=-1)
        return total * _g(self.scale)

    # ------------------------------------------------------------------ pixels and the sensor
    def _to_sensor(self, port_transmittance, lens_transmittance):
        """Broadband factor from water radiance to sensor irradiance: T_port/n_w² · T_lens π/(4N²)."""
        n = self.d["lens.f_number"]
        return _g(np.asarray(port_transmittance) / self.n_w**2 * lens_transmittance * optics.lens_irradiance_factor(n))

    def target_irradiance(self, weights):
        """Irradiance of the target's centre [W/m²] from every light (through the water)."""
        centre = np.stack([0.0 * self.altitude, 0.0 * self.altitude, self.altitude], axis=-1)[..., None, :]
        total = 0.0
        for term, to_point, r in self._light_terms(centre):
            total = total + term * np.clip(to_point[..., 2], 0.0, None) * weights.table(_g(self.scale) * r, 0)
        return total[..., 0]

    def spectra(self, weights):
        """Spectra of a scalar design per wavelength [W/m²/nm, W/m²/sr/nm]: the target centre's irradiance (on the
        target plane, and facing each light), and the water radiance along the on-axis ray (target and veil)."""
        c = weights.c * self.scale
        source = weights.s_per_lm
        centre = np.array([[0.0, 0.0, float(self.altitude)]])
        target = facing = 0.0
        for term, to_point, r in self._light_terms(centre):
            spectrum = float(term[..., 0]) * source * np.exp(-c * float(r[..., 0]))
            target = target + spectrum * float(np.clip(to_point[..., 0, 2], 0.0, None))
            facing = facing + spectrum
        value = self.d["target.reflectance"]
        m = weights.reflectance * (1.0 if isinstance(value, str) else value)
        radiance = target * m / np.pi * np.exp(-c * float(self.altitude))
        x, w = np.polynomial.legendre.leggauss(SCATTER_NODES)
        s = 0.5 * float(self.altitude) * (x + 1)
        nodes = np.stack([0 * s, 0 * s, s], axis=-1)
        for term, to_point, r in self._light_terms(nodes):
            cos_theta = -to_point[..., 2]
            veil = (
                pure_water_phase(cos_theta)[:, None] * weights.b_water
                + self.phase.phase_function(cos_theta)[:, None] * weights.b_particles
            )
            radiance = radiance + self.scale * np.sum(
                (0.5 * float(self.altitude) * w * term)[:, None] * veil * source * np.exp(-np.outer(r + s, c)), axis=0
            )
        return target, facing, radiance

    def pixel_rates(self, x_m, y_m, port_transmittance, lens_transmittance, watts: bool = False):
        """(target, veil) electron rates [e⁻/s] of pixels at image positions (x_m, y_m) (trailing sample axis), or
        with `watts` their sensor irradiances [W/m²]."""
        d = self.d
        f = _g(np.asarray(d["lens.focal_length_mm"], float) * 1e-3)
        tan_x, tan_y = np.broadcast_arrays(np.asarray(x_m, float) / f, np.asarray(y_m, float) / f)
        air = _unit(np.stack([tan_x, tan_y, np.ones_like(tan_x)], axis=-1))
        direct, veil = self.radiance(*self.rays_from_air(air), watts)
        cos_air = air[..., 2]
        corner = np.hypot(*d.sensor.size_m) / 2
        r = np.hypot(np.asarray(x_m, float), np.asarray(y_m, float))
        vignetting = cos_air**4 * (1 - _g(d["lens.mechanical_vignetting"]) * (r / corner) ** 4)
        area = 1.0 if watts else d.sensor.pixel_area_m2
        factor = self._to_sensor(port_transmittance, lens_transmittance) * vignetting * area
        return direct * factor, veil * factor

    def bare_rates(self, port_transmittance, watts: bool = False):
        """(target, veil) electron rates [e⁻/s] of a bare sensor, π ⟨L_air⟩ over its hemisphere, or with `watts`
        its irradiance [W/m²]."""
        n_u, n_phi = HEMISPHERE_SAMPLES
        u = (np.arange(n_u) + 0.5) / n_u
        phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
        q = np.sqrt(u)[:, None]
        air = np.stack(np.broadcast_arrays(q * np.cos(phi), q * np.sin(phi), np.sqrt(1 - q**2)), axis=-1)
        direct, veil = self.radiance(*self.rays_from_air(air.reshape(-1, 3)), watts)
        area = 1.0 if watts else self.d.sensor.pixel_area_m2
        factor = _g(np.pi * np.asarray(port_transmittance) / self.n_w**2) * area
        return (direct * factor).mean(axis=-1), (veil * factor).mean(axis=-1)

    def image_positions(self):
        """Midpoint grid of `IMAGE_SAMPLES_PER_AXIS`² image positions over the whole sensor (x, y) [m]."""
        n = IMAGE_SAMPLES_PER_AXIS
        u = (np.arange(n) + 0.5) / n - 0.5
        size_x, size_y = self.d.sensor.size_m
        x, y = np.meshgrid(u * size_x, u * size_y)
        return x.ravel(), y.ravel()


def is_bare(d) -> bool:
    """Whether the design is the bare sensor (f-number 1/2, `uwlab.model.optics.NO_LENS`); grids must not mix."""
    bare = np.asarray(d["lens.f_number"]) <= BARE_F_NUMBER
    if np.any(bare) and not np.all(bare):
        raise ConfigError("lens.f_number", BARE_F_NUMBER, "the extended model cannot grid the bare sensor with lenses")
    return bool(np.all(bare))
