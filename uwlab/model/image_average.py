"""The image average: the mean over the sensor of the per-pixel response.

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

from dataclasses import dataclass, field

import numpy as np

from uwlab.model import quadrature
from uwlab.model.chain import attenuating_path_m, beam_half_angle_rad, field_terms, image_prefactor, paper_beam_model
from uwlab.model.design import Design
from uwlab.model.sensor import SensorProfile
from uwlab.model.spectral_table import LogHermiteTable, image_table
from uwlab.model.weights import IMAGE_DIRECT_PATHS, IMAGE_TABLES_PER_WEIGHTS, SpectralWeights

IMAGE_SAMPLES_PER_AXIS = 16


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


def image_average_rate(d: Design, weights: SpectralWeights):
    """Mean electron rate per pixel over the sensor [e⁻/s]: the mean of `electron_rate_at_radius` over the
    image samples (`image_radii_m`), with the spectral integral from the interpolation table.

    Three routes, by the shape of the grid; all agree with the wavelength sum over every sample to 1e-8
    (tests/unit/model/test_spectral_table.py).
    - Many path lengths per lens/port geometry (altitude or attenuation axes): each geometry gets a table of the
      cumulative sums over the samples sorted by field angle (`uwlab.model.spectral_table.image_table`); the
      samples inside a beam are a prefix, and a point costs one lookup.
    - Many beam angles per path and geometry: the samples are summed directly, one lookup per sample and path,
      shared by the beams.
    - Otherwise (a single design, or a lens/port geometry per point): a Gauss rule of the sample radii
      (`_image_sum`), 8 to 24 lookups per point."""
    path = attenuating_path_m(d)
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
        angular, secant = field_terms(d, radii)
        total = np.einsum("...i,...i->...", weights.table(path[..., None] * secant, 2), angular)
    else:
        total = _image_sum(d, weights, path, focal, water, beta)
    total *= weights.table.nonzero[2]
    return image_prefactor(d, weights) * total / radii.size


IMAGE_RULES = ((8, 1.0, 2.0), (12, 2.0, 8.0), (16, 4.0, 8.0), (24, 9.0, 16.0))


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
