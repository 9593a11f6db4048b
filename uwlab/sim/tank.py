"""The tank world: a renderer of the paper's tank that is not the design model (`uwlab.sim.world`).

Geometry (camera frame: origin at the camera's entrance pupil, x right, y down, z along the optical axis; metres):
the camera looks through the tank's near wall, a flat acrylic plate (thickness t, index n_p) whose outer face is
`camera_gap_m` ahead of the pupil; the water fills the inner box x ∈ ±W/2, y ∈ ±H/2, z ∈ [z_i, z_i + L] (the
camera on the near wall's centre line); the white board (`[sim] board_size_m`, reflectance `target.reflectance`)
is centred on the far wall, every other inner surface has `[sim] surround_reflectance`. The light sits outside the
near wall too, at `light_offset_m` (above the camera: y < 0), `light_gap_m` from the wall, aimed perpendicular to
it (tilted by `light_tilt_deg` towards +y).

Light through the wall (exact, axisymmetric about the wall normal through the light): a ray leaving the light at
θ_a (q = sin θ_a) crosses the air gap h, the plate and a water depth z with lateral offset
ρ(q) = h q/√(1−q²) + t q/√(n_p²−q²) + z q/√(n_w²−q²) (Snell: n sin θ constant). For a water point at lateral
distance ρ and depth z, q is the root of ρ(q) = ρ (Newton from the paraxial guess, which lies above the root of
this convex function). The irradiance on a plane parallel to the wall is the intensity through the Jacobian of
that map: E_∥ = I(ψ) T(q) sin θ_a dθ_a / (ρ dρ) = I(ψ) T(q) / (A(q) · dρ/dq · cos θ_a) with
A = ρ/q = h/√(1−q²) + t/√(n_p²−q²) + z/√(n_w²−q²), times e^(−c z/cos θ_w); on the axis it reduces to
I T / (h + t/n_p + z/n_w)², the apparent-distance law. A surface of normal n gets E_∥ (−d_w·n)/cos θ_w; the
irradiance across the ray, E_⊥ = E_∥ / cos θ_w, drives the scattering. T is the unpolarised Fresnel
transmittance of the plate's two faces with incoherent multiple reflections, (T_s + T_p)/2 with
T = (1−R₁)(1−R₂)/(1−R₁R₂) per polarisation (Hecht, *Optics*, 5th ed., eqs. 4.42–4.45).

Beam: a generalised Lambertian I(ψ) = Φ (m+1)/(2π) cos^m ψ with m = −ln 2 / ln cos ψ½ (Moreno & Sun, "Modeling the
radiation pattern of LEDs", Optics Express 16(3), 1808–1819, 2008), ψ from the light's aim in air and ψ½ the
design's beam half-angle in air (`beam_profile` off: a top-hat cone of that half-angle).

Radiance along a camera ray in water (towards the camera): the surface it meets, ρ_s/π · E_surface · e^(−c s),
plus single-scattering path radiance L_b = ∫₀^s β(ψ) E_⊥(x) e^(−c (s_L(x) + s')) ds' (McGlamery, "A computer
model for underwater camera systems", Proc. SPIE 208, 1979; Jaffe, "Computer modeling and the design of optimal
underwater imaging systems", IEEE J. Oceanic Eng. 15(2), 101–111, 1990: the backscatter component), by
Gauss–Legendre quadrature over the ray, with β = b_w p̃_w + b_p p̃_p (`uwlab.model.scattering`), plus a stray
veil from the walls, `stray_fraction` × the on-axis board radiance, on every ray. Forward scattering (the blur
and the irradiance gain of small-angle scattering) is not rendered.

Camera: the pixel's chief ray leaves the pupil at α (tan α = r / f) and refracts through the wall; the sensor
irradiance is L_w T(q)/n_w² · T_lens(λ) π/(4N²) · cos⁴α · V(r), with V(r) = 1 − v(N) (r/r_corner)⁴ the mechanical
vignetting, v(N) = `corner_falloff_at_f2` (2/N)² (clipped to [0, 1]). The bare sensor (no lens) integrates the
radiance over its hemisphere: E = ∫ L_air cos θ dω = π ⟨L_air⟩ over a uniform grid in sin²θ and azimuth. Electron
rates: A_pixel ∫ E_s(λ) η(λ) λ/(hc) dλ, with the spectral integrals tabulated along the water path length.
Images are rendered on a coarse grid of chief rays and interpolated bilinearly to the pixels.

Spectrometer: at the target, the irradiance on its cosine collector at the board's centre, facing the light;
at the camera, a radiance probe in its enclosure just inside the near wall (`spectrometer_camera_position_m`),
aimed at the board's centre with a `spectrometer_field_deg` half-angle, reporting π × its mean radiance.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from uwlab.sim.world import WorldSettings
from uwlab.errors import ConfigError
from uwlab.model.data import read_csv_columns, resolve_path
from uwlab.model.design import Design
from uwlab.model.weights import spectral_weights
from uwlab.model.photometry import photons_per_joule
from uwlab.model.scattering import ParticleScattering, pure_water_phase
from uwlab.model.water import scattering_parts, water_iop

RAY_GRID = (40, 48)  # coarse chief-ray grid (rows, columns) of a rendered image
HEMISPHERE_GRID = (64, 96)  # bare sensor: sin²θ × azimuth samples
PROBE_GRID = 9  # camera-side spectrometer: samples per axis of its field
SCATTER_NODES = 24  # Gauss–Legendre nodes along a ray for the path radiance
PATH_STEP_M = 5e-4  # tabulation step of the spectral integrals along the water path
PATH_MAX_M = 3.0
NEWTON_STEPS = 40


@dataclass(frozen=True)
class _Rays:
    """Camera rays in water: entry points on the inner wall face, unit directions, and the factor T(q)/n_w²
    from water radiance to air radiance; `valid` is False for rays entering outside the tank."""

    origin: np.ndarray
    direction: np.ndarray
    to_air: np.ndarray
    valid: np.ndarray


class TankWorld:
    """Renders the tank (see the module docstring) for a rig's design, [sim] settings and [world] settings."""

    def __init__(self, design: Design, sim, settings: WorldSettings, base_dir: Path | None = None):
        self.settings = settings
        self.sim = sim
        self.base_dir = base_dir
        self._design = design
        self._tables: dict = {}
        width, height, length = settings.tank_size_m
        self.half = np.array([width / 2, height / 2])
        self.z_inner = settings.camera_gap_m + settings.wall_thickness_m
        self.z_far = self.z_inner + length
        self.water_index = float(design["housing.water_index"])

    # ---------------------------------------------------------------- media and spectra
    @cached_property
    def particles(self) -> ParticleScattering:
        s = self.settings
        return ParticleScattering(s.particle_b550_per_m, s.particle_scattering_exponent, s.particle_phase_function)

    def _lens_transmittance(self, design: Design, bare: bool) -> np.ndarray:
        grid = design.grid
        if bare:
            return np.ones_like(grid.nm)
        if self.settings.on("lens_transmission"):
            path = resolve_path(self.settings.lens_transmittance_csv, self.base_dir)
            table = read_csv_columns(Path(path), ("wavelength_nm", "transmittance"), "world.lens_transmittance_csv")
            return np.interp(grid.nm, table["wavelength_nm"], table["transmittance"])
        value = design["lens.transmittance"]
        if isinstance(value, str):
            return spectral_weights(design).lens_transmittance
        return np.full(grid.nm.shape, float(value))

    def _spectra(self, design: Design, bare: bool) -> dict:
        """Per-λ quantities and the path tables G(P) = Σ_λ w(λ) e^(−c(λ) P) of the electron rate per lumen:
        direct (no scattering factor), water and particle path radiance (× b_w, × b_p)."""
        key = (design.sensor.name, design["sensor.channel"], bare, None if bare else design["lens.transmittance"])
        if key not in self._tables:
            grid = design.grid
            weights = spectral_weights(design)
            iop = water_iop(design["water.type"], grid)
            scale = float(design["water.attenuation_scale"])
            b_w, b_suspended = (scale * part for part in scattering_parts(iop.b_per_m, grid.nm))
            added = self.particles.b_per_m(grid.nm)
            b_p = b_suspended + added
            c = iop.c_per_m * scale + added
            qe = design.sensor.qe_on(grid, design["sensor.channel"])
            lens = self._lens_transmittance(design, bare)
            w_e = weights.s_per_lm * lens * qe * photons_per_joule(grid.nm) * grid.w_nm
            paths = np.arange(0.0, PATH_MAX_M + PATH_STEP_M, PATH_STEP_M)
            decay = np.exp(-np.outer(paths, c))
            tables = decay @ np.stack([w_e, w_e * b_w, w_e * b_p], axis=1)
            self._tables[key] = {
                "nm": grid.nm,
                "c": c,
                "b_w": b_w,
                "b_p": b_p,
                "s_per_lm": weights.s_per_lm,
                "paths": paths,
                "tables": tables,
            }
        return self._tables[key]

    @staticmethod
    def _table(spectra: dict, column: int, path_m: np.ndarray) -> np.ndarray:
        path = np.asarray(path_m, float)
        if np.any(path > PATH_MAX_M):
            raise ConfigError("world.tank_size_m", path.max(), f"water paths beyond {PATH_MAX_M} m are not tabulated")
        return np.interp(path, spectra["paths"], spectra["tables"][:, column])

    # ---------------------------------------------------------------- the plate
    def _plate(self, q):
        """(tan θ_plate, tan θ_water, cos θ_water, Fresnel T) for rays crossing the wall with q = sin θ_air."""
        n_p, n_w = self.settings.wall_index, self.water_index
        q = np.asarray(q, float)
        cos_a = np.sqrt(1 - q**2)
        cos_p = np.sqrt(1 - (q / n_p) ** 2)
        cos_w = np.sqrt(1 - (q / n_w) ** 2)
        t = 0.0
        for pol in ("s", "p"):
            r1 = _fresnel(1.0, n_p, cos_a, cos_p, pol)
            r2 = _fresnel(n_p, n_w, cos_p, cos_w, pol)
            t = t + 0.5 * (1 - r1) * (1 - r2) / (1 - r1 * r2)
        return q / n_p / cos_p, q / n_w / cos_w, cos_w, t

    def _lateral(self, q, air_m, depth_m):
        """(ρ/q, dρ/dq) of rays crossing `air_m` of air, the plate and `depth_m` of water (module docstring)."""
        n_p, n_w, t = self.settings.wall_index, self.water_index, self.settings.wall_thickness_m
        q2 = q**2
        a = air_m / np.sqrt(1 - q2) + t / np.sqrt(n_p**2 - q2) + depth_m / np.sqrt(n_w**2 - q2)
        slope = air_m / (1 - q2) ** 1.5 + t * n_p**2 / (n_p**2 - q2) ** 1.5 + depth_m * n_w**2 / (n_w**2 - q2) ** 1.5
        return a, slope

    # ---------------------------------------------------------------- the light
    @cached_property
    def _light(self) -> dict:
        s, d = self.settings, self._design
        half = d["light.beam_half_angle_in_air_deg"]
        if half is None:
            raise ConfigError(
                "light.beam_half_angle_in_air_deg",
                None,
                "the tank world's light is outside the tank: give its beam half-angle in air",
            )
        tilt = np.radians(s.light_tilt_deg)
        return {
            "position": np.array([*s.light_offset_m, s.camera_gap_m - s.light_gap_m]),
            "aim": np.array([0.0, np.sin(tilt), np.cos(tilt)]),
            "half_angle": np.radians(float(half)),
        }

    def _intensity_per_flux(self, cos_psi):
        """I(ψ)/Φ [1/sr]: cos-power beam (module docstring) or the top-hat cone of the same half-angle."""
        half = self._light["half_angle"]
        cos_psi = np.asarray(cos_psi, float)
        if self.settings.on("beam_profile"):
            m = -np.log(2.0) / np.log(np.cos(half))
            return (m + 1) / (2 * np.pi) * np.clip(cos_psi, 0.0, None) ** m
        return np.where(cos_psi >= np.cos(half), 1.0 / (2 * np.pi * (1 - np.cos(half))), 0.0)

    def light_at(self, points: np.ndarray) -> dict:
        """The light at water points (..., 3): irradiance per unit flux on a plane parallel to the wall
        ``e_par`` [1/m²], the light's unit direction in water ``direction`` and its water path ``path_m``."""
        light = self._light
        p = np.asarray(points, float)
        lateral = p[..., :2] - light["position"][:2]
        rho = np.hypot(lateral[..., 0], lateral[..., 1])
        depth = p[..., 2] - self.z_inner
        air = self.settings.camera_gap_m - light["position"][2]
        a0, _ = self._lateral(np.zeros_like(rho), air, depth)
        q = np.minimum(rho / a0, 1 - 1e-12)
        for _ in range(NEWTON_STEPS):
            a, slope = self._lateral(q, air, depth)
            q = np.clip(q - (q * a - rho) / slope, 0.0, 1 - 1e-12)
        a, slope = self._lateral(q, air, depth)
        _, _, cos_w, fresnel = self._plate(q)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = np.where(rho[..., None] > 0, lateral / rho[..., None], 0.0)
        cos_a = np.sqrt(1 - q**2)
        air_direction = np.concatenate([unit * q[..., None], cos_a[..., None]], axis=-1)
        intensity = self._intensity_per_flux(air_direction @ light["aim"])
        sin_w = q / self.water_index
        direction = np.concatenate([unit * sin_w[..., None], cos_w[..., None]], axis=-1)
        return {"e_par": intensity * fresnel / (a * slope * cos_a), "direction": direction, "path_m": depth / cos_w}

    # ---------------------------------------------------------------- rays and radiance
    def _rays_from_air(self, air_direction: np.ndarray, origin_z: float = 0.0) -> _Rays:
        """Rays leaving a point on the axis at z = origin_z (in air) with unit directions (..., 3), into the water."""
        d = np.asarray(air_direction, float)
        q = np.hypot(d[..., 0], d[..., 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = np.where(q[..., None] > 0, d[..., :2] / q[..., None], 0.0)
        tan_p, tan_w, cos_w, fresnel = self._plate(q)
        tan_a = q / d[..., 2]
        rho = (self.settings.camera_gap_m - origin_z) * tan_a + self.settings.wall_thickness_m * tan_p
        origin = np.concatenate([unit * rho[..., None], np.full(q.shape + (1,), self.z_inner)], axis=-1)
        direction = np.concatenate([unit * (q / self.water_index)[..., None], cos_w[..., None]], axis=-1)
        valid = np.all(np.abs(origin[..., :2]) < self.half, axis=-1)
        return _Rays(origin, direction, fresnel / self.water_index**2, valid)

    def _hit(self, origin: np.ndarray, direction: np.ndarray):
        """(distance, point, inward normal, reflectance) where water rays meet the tank's inner surfaces."""
        with np.errstate(divide="ignore", invalid="ignore"):
            s_far = (self.z_far - origin[..., 2]) / direction[..., 2]
            walls = [(self.half[i] * np.sign(direction[..., i]) - origin[..., i]) / direction[..., i] for i in (0, 1)]
        candidates = np.stack([s_far, *[np.where(np.isfinite(w) & (w > 0), w, np.inf) for w in walls]], axis=-1)
        face = np.argmin(candidates, axis=-1)
        distance = np.take_along_axis(candidates, face[..., None], axis=-1)[..., 0]
        point = origin + distance[..., None] * direction
        normal = np.zeros(point.shape)
        normal[..., 2] = np.where(face == 0, -1.0, 0.0)
        for i in (0, 1):
            normal[..., i] = np.where(face == i + 1, -np.sign(direction[..., i]), normal[..., i])
        board = (face == 0) & np.all(np.abs(point[..., :2]) <= np.asarray(self.sim.board_size_m) / 2, axis=-1)
        reflectance = np.where(board, self._board_reflectance, self.sim.surround_reflectance)
        return distance, point, normal, reflectance

    @cached_property
    def _board_reflectance(self) -> float:
        value = self._design["target.reflectance"]
        if isinstance(value, str):
            raise ConfigError("target.reflectance", value, "the simulated rig needs a number")
        return float(value)

    def _surface_irradiance(self, point, normal):
        """(E per unit flux on the surface [1/m²], light water path [m]) at surface points."""
        light = self.light_at(point)
        cos_in = np.clip(-np.sum(light["direction"] * normal, axis=-1), 0.0, None)
        return light["e_par"] * cos_in / light["direction"][..., 2], light["path_m"]

    def _scatter_geometry(self, origin, direction, length):
        """Gauss–Legendre nodes along rays: (weight × E_⊥ per unit flux, p̃_w, p̃_p, total water path) with the
        node axis last."""
        x, w = np.polynomial.legendre.leggauss(SCATTER_NODES)
        s = 0.5 * length[..., None] * (x + 1)
        weights = 0.5 * length[..., None] * w
        points = origin[..., None, :] + s[..., None] * direction[..., None, :]
        light = self.light_at(points)
        cos_psi = -np.sum(light["direction"] * direction[..., None, :], axis=-1)
        e_perp = light["e_par"] / light["direction"][..., 2]
        return weights * e_perp, pure_water_phase(cos_psi), self.particles.phase_function(cos_psi), light["path_m"] + s

    def _stray_radiance_rate(self, spectra: dict) -> float:
        """The stray veil: `stray_fraction` × the direct radiance of the board's centre at the camera (rate units)."""
        if not self.settings.on("stray_light"):
            return 0.0
        centre = np.array([0.0, 0.0, self.z_far])
        e, path = self._surface_irradiance(centre, np.array([0.0, 0.0, -1.0]))
        return float(
            self.settings.stray_fraction
            * self._board_reflectance
            / np.pi
            * e
            * self._table(spectra, 0, path + (self.z_far - self.z_inner))
        )

    def _radiance_rate(self, rays: _Rays, spectra: dict) -> np.ndarray:
        """Water radiance along each ray, in electron-rate units per lumen (the spectral weights applied)."""
        distance, point, normal, reflectance = self._hit(rays.origin, rays.direction)
        e, path = self._surface_irradiance(point, normal)
        total = reflectance / np.pi * e * self._table(spectra, 0, path + distance)
        if self.settings.on("backscatter"):
            weight, p_w, p_p, paths = self._scatter_geometry(rays.origin, rays.direction, distance)
            scattered = p_w * self._table(spectra, 1, paths) + p_p * self._table(spectra, 2, paths)
            total = total + np.sum(weight * scattered, axis=-1)
        return np.where(rays.valid, total + self._stray_radiance_rate(spectra), 0.0)

    # ---------------------------------------------------------------- what the instruments see
    def _flux_lm(self, design: Design) -> float:
        return float(design["light.luminous_flux_lm"]) * self.sim.light_efficiency

    def _vignetting(self, design: Design, r_m: np.ndarray, cos_air: np.ndarray) -> np.ndarray:
        if not self.settings.on("vignetting"):
            return np.ones_like(r_m)
        corner = np.hypot(*design.sensor.size_m) / 2
        falloff = np.clip(self.settings.corner_falloff_at_f2 * (2.0 / float(design["lens.f_number"])) ** 2, 0.0, 1.0)
        return cos_air**4 * np.clip(1 - falloff * (r_m / corner) ** 4, 0.0, 1.0)

    def pixel_rates(self, design: Design, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Electron rate [e⁻/s] at full light of pixels at sensor positions (x_m, y_m) (any matching shapes)."""
        focal = float(design["lens.focal_length_mm"]) * 1e-3
        x, y = np.broadcast_arrays(np.asarray(x_m, float), np.asarray(y_m, float))
        air = np.stack([x / focal, y / focal, np.ones_like(x)], axis=-1)
        air /= np.linalg.norm(air, axis=-1, keepdims=True)
        spectra = self._spectra(design, bare=False)
        rays = self._rays_from_air(air)
        radiance = self._radiance_rate(rays, spectra) * rays.to_air
        vignetting = self._vignetting(design, np.hypot(x, y), air[..., 2])
        camera = np.pi / (4 * float(design["lens.f_number"]) ** 2) * vignetting
        return self._flux_lm(design) * design.sensor.pixel_area_m2 * camera * radiance

    def bare_sensor_rate(self, design: Design) -> float:
        """Electron rate [e⁻/s] at full light of a bare sensor: π × its hemisphere's mean air radiance."""
        n_u, n_phi = HEMISPHERE_GRID
        u = (np.arange(n_u) + 0.5) / n_u
        phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
        q = np.sqrt(u)[:, None]
        air = np.stack(np.broadcast_arrays(q * np.cos(phi), q * np.sin(phi), np.sqrt(1 - q**2)), axis=-1)
        spectra = self._spectra(design, bare=True)
        rays = self._rays_from_air(air)
        mean = float(np.mean(self._radiance_rate(rays, spectra) * rays.to_air))
        return self._flux_lm(design) * design.sensor.pixel_area_m2 * np.pi * mean

    def rate_map(self, design: Design, bare: bool, shape_yx: tuple[int, int]) -> np.ndarray:
        """Per-pixel electron rate [e⁻/s] (float32) at full light for an image of `shape_yx` covering the sensor."""
        if bare:
            return np.full(shape_yx, self.bare_sensor_rate(design), np.float32)
        ny, nx = shape_yx
        size_x, size_y = design.sensor.size_m
        x = (np.arange(nx) + 0.5) / nx * size_x - size_x / 2
        y = (np.arange(ny) + 0.5) / ny * size_y - size_y / 2
        rows, columns = (min(n, m) for n, m in zip(RAY_GRID, shape_yx, strict=True))
        cx = np.linspace(x[0], x[-1], columns) if columns > 1 else x[:1]
        cy = np.linspace(y[0], y[-1], rows) if rows > 1 else y[:1]
        coarse = self.pixel_rates(design, cx[None, :], cy[:, None])
        if rows == ny and columns == nx:
            return coarse.astype(np.float32)
        if min(rows, columns) < 2:
            return np.broadcast_to(coarse, shape_yx).astype(np.float32)
        # imported here: scipy.interpolate takes 0.3 s to import, and the serial simulators (a process per
        # instrument, per rig) import this module for the spectrometer's light and never draw an image
        from scipy.interpolate import RectBivariateSpline

        return np.asarray(RectBivariateSpline(cy, cx, coarse, kx=1, ky=1)(y, x), np.float32)

    def centre_rate(self, design: Design, bare: bool) -> float:
        """Electron rate [e⁻/s] at full light of the image centre (or of the bare sensor)."""
        if bare:
            return self.bare_sensor_rate(design)
        return float(self.pixel_rates(design, np.zeros(1), np.zeros(1))[0])

    def board_roi(self, design: Design, shape_yx: tuple[int, int]) -> tuple[int, int, int, int]:
        """The board's footprint (x, y, width, height) in pixels: the chief rays that meet the board."""
        ny, nx = shape_yx
        size_x, size_y = design.sensor.size_m
        focal = float(design["lens.focal_length_mm"]) * 1e-3
        inside = []
        for n, size, axis in ((nx, size_x, 0), (ny, size_y, 1)):
            pos = (np.arange(n) + 0.5) / n * size - size / 2
            air = np.zeros((n, 3))
            air[:, axis] = pos / focal
            air[:, 2] = 1.0
            air /= np.linalg.norm(air, axis=-1, keepdims=True)
            rays = self._rays_from_air(air)
            _, point, _, _ = self._hit(rays.origin, rays.direction)
            on = np.abs(point[:, axis]) <= self.sim.board_size_m[axis] / 2
            inside.append(np.flatnonzero(on))
        (x0, x1), (y0, y1) = ((i.min(), i.max() + 1) if i.size else (0, 0) for i in inside)
        return int(x0), int(y0), int(x1 - x0), int(y1 - y0)

    def spectral_irradiance(self, design: Design, position: str) -> tuple[np.ndarray, np.ndarray]:
        """(wavelength_nm, W/m²/nm) at full light that the spectrometer measures at `position`."""
        spectra = self._spectra(design, bare=True)
        phi = self._flux_lm(design) * spectra["s_per_lm"]
        c = spectra["c"]
        if position == "target":
            light = self.light_at(np.array([0.0, 0.0, self.z_far]))
            facing = light["e_par"] / light["direction"][2]
            return spectra["nm"], phi * facing * np.exp(-c * light["path_m"])
        return spectra["nm"], phi * np.pi * self._probe_radiance_per_flux(spectra)

    def _probe_radiance_per_flux(self, spectra: dict) -> np.ndarray:
        """Mean spectral radiance per unit spectral flux over the camera-side probe's field (per λ)."""
        s = self.settings
        half = np.tan(np.radians(s.spectrometer_field_deg))
        u = np.linspace(-half, half, PROBE_GRID)
        tx, ty = np.meshgrid(u, u)
        keep = np.hypot(tx, ty) <= half
        position = np.array(s.spectrometer_camera_position_m) + [0, 0, self.z_inner]
        axis = np.array([0.0, 0.0, self.z_far]) - position
        axis /= np.linalg.norm(axis)
        side = np.cross(axis, [1.0, 0.0, 0.0])
        side /= np.linalg.norm(side)
        up = np.cross(side, axis)
        direction = axis + tx[keep][:, None] * up + ty[keep][:, None] * side
        direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
        origin = np.broadcast_to(position, direction.shape)
        distance, point, normal, reflectance = self._hit(origin, direction)
        e, path = self._surface_irradiance(point, normal)
        c = spectra["c"]
        total = (reflectance / np.pi * e)[:, None] * np.exp(-np.outer(path + distance, c))
        if s.on("backscatter"):
            weight, p_w, p_p, paths = self._scatter_geometry(origin, direction, distance)
            decay = np.exp(-paths[..., None] * c)
            total = total + np.sum(
                weight[..., None] * decay * (p_w[..., None] * spectra["b_w"] + p_p[..., None] * spectra["b_p"]), axis=1
            )
        if s.on("stray_light"):
            centre = np.array([0.0, 0.0, self.z_far])
            e0, path0 = self._surface_irradiance(centre, np.array([0.0, 0.0, -1.0]))
            total = total + s.stray_fraction * self._board_reflectance / np.pi * e0 * np.exp(
                -c * (path0 + self.z_far - self.z_inner)
            )
        return total.mean(axis=0)


def _fresnel(n1, n2, cos_i, cos_t, pol):
    """Fresnel reflectance for polarisation "s" or "p" (Hecht, *Optics*, 5th ed., eqs. 4.42–4.43)."""
    if pol == "s":
        r = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    else:
        r = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
    return r**2
