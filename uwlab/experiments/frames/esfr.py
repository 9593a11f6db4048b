"""Slanted-edge MTF: the edge-based spatial frequency response (e-SFR) of ISO 12233:2017, Annex D.

The procedure, per edge, as the standard writes it (and as Burns' reference implementation ``sfrmat`` does):

1. The region of interest holds one straight edge between a dark and a bright side, tilted from the pixel grid
   (the standard's target tilts it about 5°). A near-horizontal edge is transposed into a near-vertical one, and a
   bright-to-dark edge is mirrored so that the signal rises with x.
2. The edge is located in each row: the centroid of the row's discrete derivative (``[-1/2, +1/2]``, value at
   x + ½) under a Hamming window; a straight line x_e(y) = a + b·y is fitted to the centroids by least squares,
   then the centroids are taken again under windows centred on that line and the line refitted. The edge angle is
   atan(b) from the pixel column; within 2° of the grid the phases of the rows do not fill the bins (refused).
3. Every pixel is projected onto the edge normal: d = (x − x_e(y))·cos θ, its signed distance from the edge in
   pixels; the values are averaged in bins of a quarter pixel (4× oversampling): the edge spread function (ESF).
4. The line spread function (LSF) is the ESF's central difference ``[-1/2, 0, +1/2]``, multiplied by a Hamming
   window centred on its centroid; the MTF is the modulus of its discrete Fourier transform normalised to 1 at
   zero frequency, on frequencies k / (N·Δ) in cycles per pixel *normal to the edge* (Δ = ¼ px).
5. Two corrections, each the inverse of a known transfer function: the central difference's, sin(2πfΔ)/(2πfΔ)
   (the standard's "derivative correction", ``fir2fix`` in sfrmat3), and the quarter-pixel bin's, a box of width
   Δ, sin(πfΔ)/(πfΔ) (ours: the bin averages the ESF over its width; without it MTF50 of a sharp edge reads
   about 1 % low). Both are capped at a factor of 10, as sfrmat caps its correction.

Conventions: frequencies in cycles per (sensor) pixel along the edge normal; Nyquist is 0.5 cy/px; MTF50 is the
lowest frequency where the MTF falls to 0.5 (linear interpolation). The MTF includes everything between the edge
and the numbers: optics, defocus, motion, and the pixel aperture (a square pixel seen across an edge at θ has
sinc(f cos θ)·sinc(f sin θ)).

A colour filter array (Bayer mosaic) is measured per channel: only the channel's sites enter, each at its own
position on the sensor, so the channel's MTF is on the same frequency axis (cycles per sensor pixel) as a
monochrome camera's; a channel samples the plane every 2 px, so the edge must span more rows to fill the bins.

>>> import numpy as np
>>> from scipy.special import erf
>>> y, x = np.mgrid[0:100, 0:100]
>>> theta = np.radians(5.0)
>>> d = ((x - 50) - np.tan(theta) * (y - 50)) * np.cos(theta)    # signed distance from the edge, px
>>> image = 100 + 800 * 0.5 * (1 + erf(d / (1.0 * np.sqrt(2))))  # a Gaussian-blurred edge, σ = 1 px
>>> edge = slanted_edge(image)
>>> round(edge.angle_deg, 2), round(edge.mtf50_cy_per_px, 3)     # closed form: 0.1874 / σ
(5.0, 0.188)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError

OVERSAMPLING = 4  # bins per pixel (ISO 12233: a quarter pixel)
MIN_ANGLE_DEG = 2.0  # closer to the pixel grid, the rows' phases do not fill the quarter-pixel bins
MAX_CORRECTION = 10.0  # the derivative and bin corrections' cap (sfrmat's)
MIN_ROWS = 16  # rows needed to fit the edge line
MIN_CONTRAST_NOISE = 10.0  # the edge's step over the noise below which no edge is taken
SATURATED_FRACTION = 0.001  # pixels at the image's full scale above which the edge is clipped
NYQUIST_CY_PER_PX = 0.5
MAX_FREQUENCY_CY_PER_PX = 1.0  # the curve is reported up to the sampling frequency
WINDOW_MIN_PX = 2.5  # the LSF window's flat half-width: at least this many pixels,
WINDOW_RISES = 3.0  # and this many 10-90 % rise distances of the edge


@dataclass(frozen=True)
class EdgeMTF:
    """One edge's e-SFR: its angle from the nearest pixel axis (degrees, signed), where it lies (the ROI x, y, w, h
    in the full image), MTF50 and the MTF at Nyquist, and the curve (``frequency_cy_per_px``, ``mtf``)."""

    angle_deg: float
    roi: tuple[int, int, int, int]
    orientation: str  # "vertical" (the edge runs along the columns) or "horizontal"
    mtf50_cy_per_px: float
    mtf_nyquist: float
    frequency_cy_per_px: np.ndarray
    mtf: np.ndarray
    esf: np.ndarray
    contrast: float  # the edge's step (bright − dark plateau) in the image's units

    def to_json(self) -> dict:
        return {
            "angle_deg": self.angle_deg,
            "roi": list(self.roi),
            "orientation": self.orientation,
            "mtf50_cy_per_px": self.mtf50_cy_per_px,
            "mtf_nyquist": self.mtf_nyquist,
            "frequency_cy_per_px": self.frequency_cy_per_px.tolist(),
            "mtf": self.mtf.tolist(),
        }


def _full_scale(image: np.ndarray) -> float | None:
    """The largest value an integer image can hold (its clip level when nothing else is known); None for floats."""
    return float(np.iinfo(image.dtype).max) if np.issubdtype(image.dtype, np.integer) else None


def _row_centroids(rows: np.ndarray, centres: np.ndarray | None, half_width: float) -> tuple[np.ndarray, np.ndarray]:
    """Per row, the centroid (in sample units, x + ½ of the difference) of the derivative under a Hamming window
    centred at ``centres`` (the row's middle when None); and whether the row had a usable derivative."""
    n_rows, n_cols = rows.shape
    derivative = np.diff(rows, axis=1)  # value at x + 1/2
    x = np.arange(n_cols - 1) + 0.5
    centre = np.full(n_rows, (n_cols - 1) / 2.0) if centres is None else centres
    offset = (x[None, :] - centre[:, None]) / half_width
    window = np.where(np.abs(offset) <= 1.0, 0.54 + 0.46 * np.cos(np.pi * offset), 0.0)
    weighted = derivative * window
    total = weighted.sum(axis=1)
    ok = total > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        centroid = (weighted * x[None, :]).sum(axis=1) / total
    return centroid, ok


def _fit_line(planes: list[tuple[np.ndarray, float, float, float]]) -> tuple[float, float]:
    """The edge line x = a + b·y in full-image pixel coordinates, from the row centroids of each sampling plane
    ``(rows, x0, y0, step)`` (a plane's sample (i, j) lies at x0 + step·j, y0 + step·i), fitted twice (module
    docstring, step 2)."""
    line: tuple[float, float] | None = None
    for _ in range(2):
        ys, xs = [], []
        for rows, x0, y0, step in planes:
            y_rows = y0 + step * np.arange(rows.shape[0])
            centres = None if line is None else (line[0] + line[1] * y_rows - x0) / step
            half = (rows.shape[1] - 1) / 2.0 if line is None else max(4.0, rows.shape[1] / 4.0)
            centroid, ok = _row_centroids(rows, centres, half)
            ys.append(y_rows[ok])
            xs.append(x0 + step * centroid[ok])
        y_all, x_all = np.concatenate(ys), np.concatenate(xs)
        if y_all.size < MIN_ROWS // 2:
            raise ConfigError("roi", None, "no edge: too few rows cross the edge")
        b, a = np.polyfit(y_all, x_all, 1)
        line = (float(a), float(b))
    assert line is not None
    a, b = line
    return a, b


def _bin_esf(d: np.ndarray, values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """The ESF: mean of ``values`` in quarter-pixel bins of ``d`` over [lo, hi); empty bins (too few rows for a
    phase) are interpolated from their neighbours, as sfrmat does."""
    step = 1.0 / OVERSAMPLING
    n_bins = int(np.floor((hi - lo) / step))
    index = np.floor((d - lo) / step).astype(np.int64)
    inside = (index >= 0) & (index < n_bins)
    sums = np.bincount(index[inside], weights=values[inside], minlength=n_bins)
    counts = np.bincount(index[inside], minlength=n_bins)
    filled = counts > 0
    if filled.sum() < 0.9 * n_bins:
        raise ConfigError("roi", None, "the edge's rows do not fill the quarter-pixel bins (too few rows?)")
    centres = lo + step * (np.arange(n_bins) + 0.5)
    esf = np.empty(n_bins)
    esf[filled] = sums[filled] / counts[filled]
    esf[~filled] = np.interp(centres[~filled], centres[filled], esf[filled])
    return esf


def _mtf_from_esf(esf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (cy/px) and MTF from a quarter-pixel ESF (module docstring, steps 4–5)."""
    step = 1.0 / OVERSAMPLING
    lsf = np.zeros_like(esf)
    lsf[1:-1] = (esf[2:] - esf[:-2]) / 2.0
    lsf[0], lsf[-1] = lsf[1], lsf[-2]
    n = lsf.size
    positions = np.arange(n)
    weight = np.clip(lsf, 0, None)
    centre = float((weight * positions).sum() / weight.sum()) if weight.sum() > 0 else n / 2.0
    # The window: flat over the LSF and a cosine taper beyond, from the edge's 10–90 % rise distance (module
    # docstring): the noise of the plateaus far from the edge stays out, the LSF's tails stay in.
    rising = (esf - esf[: max(1, n // 8)].mean()) / max(
        esf[-max(1, n // 8) :].mean() - esf[: max(1, n // 8)].mean(), 1e-300
    )
    rise_bins = float(np.interp(0.9, np.maximum.accumulate(rising), positions)) - float(
        np.interp(0.1, np.maximum.accumulate(rising), positions)
    )
    flat = max(WINDOW_MIN_PX * OVERSAMPLING, WINDOW_RISES * rise_bins)
    distance = np.abs(positions - centre)
    window = np.where(
        distance <= flat, 1.0, np.where(distance <= 2 * flat, 0.5 + 0.5 * np.cos(np.pi * (distance - flat) / flat), 0.0)
    )
    spectrum = np.abs(np.fft.rfft(lsf * window))
    if spectrum[0] <= 0:
        raise ConfigError("roi", None, "no edge: the line spread function has no area")
    frequency = np.fft.rfftfreq(n, d=step)
    argument = np.pi * frequency * step
    with np.errstate(invalid="ignore", divide="ignore"):
        derivative = np.where(argument > 0, np.sin(2 * argument) / (2 * argument), 1.0)
        box = np.where(argument > 0, np.sin(argument) / argument, 1.0)
    correction = np.minimum(1.0 / np.clip(np.abs(derivative * box), 1e-12, None), MAX_CORRECTION)
    mtf = spectrum / spectrum[0] * correction
    keep = frequency <= MAX_FREQUENCY_CY_PER_PX + 1e-9
    return frequency[keep], mtf[keep]


def mtf50(frequency: np.ndarray, mtf: np.ndarray) -> float:
    """The lowest frequency where ``mtf`` falls to 0.5, by linear interpolation; NaN where it never does.

    >>> round(mtf50(np.array([0.0, 0.1, 0.2]), np.array([1.0, 0.6, 0.4])), 6)
    0.15
    """
    below = np.flatnonzero(mtf < 0.5)
    if below.size == 0 or below[0] == 0:
        return float("nan")
    i = below[0]
    f0, f1, m0, m1 = frequency[i - 1], frequency[i], mtf[i - 1], mtf[i]
    return float(f0 + (m0 - 0.5) * (f1 - f0) / (m0 - m1))


def slanted_edge(
    image: np.ndarray,
    roi: tuple[int, int, int, int] | None = None,
    sites: tuple[tuple[int, int], ...] | None = None,
    saturation: float | None = None,
) -> EdgeMTF:
    """The e-SFR of the one edge in ``roi`` (x, y, w, h; default: the whole image) of a 2-D ``image``.

    ``sites``: the (row, column) offsets in the 2 × 2 cell of the colour channel to measure (`bayer_sites`), e.g.
    ``((0, 0),)`` for red in an RG mosaic; None: every pixel (a monochrome image). ``saturation``: the clip level
    (default: an integer image's full scale). Refused with a `ConfigError` on ``roi``: no edge (a step not above
    the noise), an edge within 2° of the pixel grid, a clipped edge.
    """
    image = np.asarray(image)
    if image.ndim != 2:
        raise ConfigError("image", list(image.shape), "must be one 2-D plane (a monochrome or raw Bayer image)")
    height, width = image.shape
    x0, y0, w, h = roi if roi is not None else (0, 0, width, height)
    if w < 8 or h < 8 or x0 < 0 or y0 < 0 or x0 + w > width or y0 + h > height:
        raise ConfigError("roi", [x0, y0, w, h], f"must lie within the {width}x{height} image and be ≥ 8 px a side")
    crop = image[y0 : y0 + h, x0 : x0 + w].astype(np.float64)
    clip = saturation if saturation is not None else _full_scale(image)
    if clip is not None and np.count_nonzero(crop >= clip) > SATURATED_FRACTION * crop.size:
        raise ConfigError("roi", [x0, y0, w, h], f"the edge is saturated (pixels at {clip:g}): lower the exposure")
    # The sites' offsets in the crop's own 2 × 2 cell (an odd ROI origin shifts the phase).
    cells = tuple(((r - y0) % 2, (c - x0) % 2) for r, c in sites) if sites is not None else ((0, 0),)
    step = 1 if sites is None else 2

    # Orientation: the edge runs along the axis with the smaller mean gradient.
    gx = np.abs(np.diff(crop, axis=1)).mean()
    gy = np.abs(np.diff(crop, axis=0)).mean()
    vertical = bool(gx >= gy)
    plane = crop if vertical else crop.T
    ph, pw = plane.shape
    # Sample positions of the measured sites, in the (possibly transposed) crop's pixel coordinates.
    cell_offsets = [(c, r) if vertical else (r, c) for r, c in cells]  # (column, row) offsets in `plane`
    dark_first = plane[:, : pw // 4].mean() <= plane[:, -(pw // 4) :].mean()
    if not dark_first:
        plane = plane[:, ::-1]
        cell_offsets = [(((pw - 1 - cx) % 2) if step == 2 else 0, cy) for cx, cy in cell_offsets]

    # Plateaus and noise: the step must stand clear of the noise.
    side = max(2, pw // 6)
    # A channel's own sites (every pixel of a monochrome image): a mosaic's neighbours are other colours.
    cx0, cy0 = cell_offsets[0]
    left = plane[cy0::step, cx0:side:step]
    right = plane[cy0::step, pw - side + (cx0 - (pw - side)) % step : pw : step]
    contrast = float(np.median(right) - np.median(left))
    noise = float(np.median(np.abs(np.diff(left, axis=0)))) / 0.6745 / np.sqrt(2) if left.shape[0] > 1 else 0.0
    if not contrast > MIN_CONTRAST_NOISE * max(noise, 1e-12 * max(1.0, abs(contrast))):
        raise ConfigError("roi", [x0, y0, w, h], f"no edge: a step of {contrast:.3g} against noise {noise:.3g}")

    planes = []
    for cx, cy in cell_offsets:
        sub = plane[cy::step, cx::step]
        planes.append((sub, float(cx), float(cy), float(step)))
    if sum(p[0].shape[0] for p in planes) < MIN_ROWS:
        raise ConfigError("roi", [x0, y0, w, h], f"no edge: fewer than {MIN_ROWS} rows")
    a, b = _fit_line(planes)
    angle = float(np.degrees(np.arctan(b)))
    if abs(angle) < MIN_ANGLE_DEG:
        raise ConfigError(
            "roi", [x0, y0, w, h], f"the edge is {angle:.2f}° from the pixel grid: tilt it by ≥ {MIN_ANGLE_DEG:g}°"
        )
    if abs(angle) > 45.0:
        raise ConfigError("roi", [x0, y0, w, h], f"no straight edge along one axis (fitted angle {angle:.1f}°)")
    cos = float(np.cos(np.arctan(b)))

    ds, values = [], []
    for sub, px, py, pitch in planes:
        ys = py + pitch * np.arange(sub.shape[0])[:, None]
        xs = px + pitch * np.arange(sub.shape[1])[None, :]
        ds.append(((xs - (a + b * ys)) * cos).ravel())
        values.append(sub.ravel())
    d, v = np.concatenate(ds), np.concatenate(values)
    # The distance range every row covers (rows meet the edge at different x).
    edge_top, edge_bottom = a, a + b * (ph - 1)
    lo = (0.0 - min(edge_top, edge_bottom)) * cos
    hi = (pw - 1 - max(edge_top, edge_bottom)) * cos
    if hi - lo < 8.0 or lo > -2.0 or hi < 2.0:
        raise ConfigError("roi", [x0, y0, w, h], "the edge lies too close to the ROI's side: centre it in the ROI")
    esf = _bin_esf(d, v, lo, hi)
    frequency, mtf = _mtf_from_esf(esf)
    return EdgeMTF(
        angle_deg=angle,
        roi=(int(x0), int(y0), int(w), int(h)),
        orientation="vertical" if vertical else "horizontal",
        mtf50_cy_per_px=mtf50(frequency, mtf),
        mtf_nyquist=float(np.interp(NYQUIST_CY_PER_PX, frequency, mtf)),
        frequency_cy_per_px=frequency,
        mtf=mtf,
        esf=esf,
        contrast=contrast,
    )


def find_edges(image: np.ndarray, min_length_px: int = 40) -> list[tuple[int, int, int, int]]:
    """ROIs (x, y, w, h) around the straight edges of an image of dark and bright regions (a slanted-edge chart):
    the image is thresholded at Otsu's level, the boundaries of its bright regions simplified to polygons, and each
    side of at least ``min_length_px`` that is not within 2° of the pixel grid (as the image's border is) gives
    the ROI of its middle 60 %, reaching across the edge a quarter of the side's length each way."""
    import cv2

    plane = np.asarray(image, dtype=np.float64)
    lo, hi = np.percentile(plane, [1, 99])
    if hi <= lo:
        return []
    scaled = np.clip((plane - lo) / (hi - lo) * 255.0, 0, 255).astype(np.uint8)
    smooth = cv2.GaussianBlur(scaled, (5, 5), 0)
    _, mask = cv2.threshold(smooth, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    contours, _ = cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    height, width = plane.shape
    rois = []
    for contour in contours:
        if cv2.arcLength(contour, True) < 2 * min_length_px:
            continue
        polygon = cv2.approxPolyDP(contour, max(2.0, 0.01 * cv2.arcLength(contour, True)), True)[:, 0, :]
        for p, q in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
            dx, dy = float(q[0] - p[0]), float(q[1] - p[1])
            length = float(np.hypot(dx, dy))
            if length < min_length_px:
                continue
            vertical = abs(dy) >= abs(dx)
            tilt = np.degrees(np.arctan2(abs(dx), abs(dy)) if vertical else np.arctan2(abs(dy), abs(dx)))
            if tilt < MIN_ANGLE_DEG:  # the image's own border, too, runs along the grid
                continue
            mx, my = (p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0
            along = 0.3 * (abs(dy) if vertical else abs(dx))
            across = max(12.0, 0.25 * length) + 0.5 * (abs(dx) if vertical else abs(dy))
            half_w, half_h = (across, along) if vertical else (along, across)
            x_a, x_b = int(max(0, np.floor(mx - half_w))), int(min(width, np.ceil(mx + half_w)))
            y_a, y_b = int(max(0, np.floor(my - half_h))), int(min(height, np.ceil(my + half_h)))
            if x_b - x_a >= 16 and y_b - y_a >= 16:
                rois.append((x_a, y_a, x_b - x_a, y_b - y_a))
    return sorted(rois, key=lambda r: (r[1], r[0]))


def slanted_edges(
    image: np.ndarray,
    roi: tuple[int, int, int, int] | None = None,
    sites: tuple[tuple[int, int], ...] | None = None,
    saturation: float | None = None,
) -> list[EdgeMTF]:
    """Every edge's e-SFR: the one edge of ``roi`` when given (its refusals raised), else each edge `find_edges`
    finds (edges it cannot measure are left out); a `ConfigError` when none is measured."""
    if roi is not None:
        return [slanted_edge(image, roi, sites, saturation)]
    found = []
    last: ConfigError | None = None
    for box in find_edges(image):
        try:
            found.append(slanted_edge(image, box, sites, saturation))
        except ConfigError as exc:
            last = exc
    if not found:
        reason = f"no measurable edge found ({last.reason})" if last else "no straight slanted edge found"
        raise ConfigError("image", None, reason)
    return found


CHANNELS = ("red", "green", "blue")
MAX_IMAGE_BYTES = 1_000_000_000
# ITU-R BT.709 luma weights, the luminance sfrmat (ISO 12233's reference code) measures an RGB image on.
LUMA_WEIGHTS = (0.2126, 0.7152, 0.0722)


def read_image(path: str) -> np.ndarray:
    """A TIFF (tifffile) or PNG (OpenCV) as it is stored: (H, W) or (H, W, 3) in R, G, B order, 8 or 16 bit (or
    float); read through the bounded regular-file reader (`uwlab.model.data.read_bytes`)."""
    import io

    from uwlab.model.data import read_bytes

    data = read_bytes(Path(path), "image", MAX_IMAGE_BYTES, "image")
    if data[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        import tifffile

        try:
            image = tifffile.imread(io.BytesIO(data))
        except (ValueError, KeyError, NotImplementedError, tifffile.TiffFileError) as exc:
            raise ConfigError("image", path, f"not a readable TIFF ({exc})") from None
    else:
        import cv2

        decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if decoded is None:
            raise ConfigError("image", path, "not a TIFF or PNG image OpenCV can decode")
        image = decoded[..., 2::-1] if decoded.ndim == 3 and decoded.shape[2] >= 3 else decoded  # BGR(A) → RGB
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 4:
        image = image[..., :3]
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
        raise ConfigError("image", path, f"shape {list(image.shape)}: expected one plane or three (RGB)")
    return image


def _roi(text: str | tuple[int, int, int, int] | None) -> tuple[int, int, int, int] | None:
    if text is None or isinstance(text, tuple):
        return text
    parts = text.split(",")
    try:
        x, y, w, h = (int(p) for p in parts)
    except ValueError:
        raise ConfigError("roi", text, "expected X,Y,W,H in whole pixels") from None
    return x, y, w, h


def measure_image(
    path: str,
    roi: str | tuple[int, int, int, int] | None = None,
    channel: str | None = None,
    bayer: str | None = None,
) -> list[EdgeMTF]:
    """`slanted_edges` of an image file: ``channel`` picks a plane of an RGB image (default: its BT.709 luminance)
    or, with ``bayer`` (the mosaic's layout, e.g. ``"RG"``), that channel's sites of a raw mosaic."""
    from uwlab.drivers.camera.pixels import bayer_sites

    image = read_image(path)
    if channel is not None and channel not in CHANNELS:
        raise ConfigError("channel", channel, f"expected one of {', '.join(CHANNELS)}")
    sites = None
    saturation = _full_scale(image)
    if image.ndim == 3:
        if bayer is not None:
            raise ConfigError("bayer", bayer, "the image has three colour planes: it is not a raw mosaic")
        plane = (
            image[..., CHANNELS.index(channel)].astype(np.float64)
            if channel is not None
            else np.tensordot(image.astype(np.float64), LUMA_WEIGHTS, axes=([2], [0]))
        )
        if saturation is not None and np.any(image.max(axis=2) >= saturation) and channel is None:
            # A pixel clipped in any plane clips the luminance: count it as the plane's full scale.
            plane = np.where(image.max(axis=2) >= saturation, saturation, plane)
    else:
        plane = image
        if channel is not None:
            if bayer is None:
                raise ConfigError(
                    "channel", channel, "a one-plane image has channels only as a Bayer mosaic: give --bayer"
                )
            sites = bayer_sites(bayer)[channel[0].upper()]
        elif bayer is not None:
            raise ConfigError("bayer", bayer, "give --channel red|green|blue to measure one channel of the mosaic")
    return slanted_edges(plane, _roi(roi), sites, saturation)


def measure_edge(
    image: np.ndarray,
    roi: tuple[int, int, int, int] | None = None,
    bayer: str | None = None,
    saturation: float | None = None,
) -> dict[str | None, EdgeMTF]:
    """The e-SFR of the one slanted edge of a sweep point's image (a mean of frames): in ``roi``, else in the largest
    region `find_edges` finds that measures. A raw Bayer mosaic (``bayer``, its layout at the image's origin) is
    measured per channel on its own sites, with the edge found on the mosaic averaged over 2 × 2 cells; the result
    maps ``None`` to the edge over every pixel (a monochrome image) or the green channel's (a mosaic: green samples
    the plane densest), and each channel name to its own. `ConfigError` (key ``edge_roi``) when no edge measures."""
    from uwlab.drivers.camera.pixels import bayer_sites

    plane = np.asarray(image, dtype=np.float64)
    sites = bayer_sites(bayer) if bayer is not None else None

    def measure(box: tuple[int, int, int, int]) -> dict[str | None, EdgeMTF]:
        if sites is None:
            return {None: slanted_edge(plane, box, None, saturation)}
        found: dict[str | None, EdgeMTF] = {
            name: slanted_edge(plane, box, sites[name[0].upper()], saturation) for name in CHANNELS
        }
        return {None: found["green"], **found}

    try:
        if roi is not None:
            return measure(roi)
        import cv2

        search = cv2.blur(plane, (2, 2)) if sites is not None else plane
        last: ConfigError | None = None
        for box in sorted(find_edges(search), key=lambda r: -r[2] * r[3]):
            try:
                return measure(box)
            except ConfigError as exc:
                last = exc
        reason = f"no measurable edge found ({last.reason})" if last else "no straight slanted edge found"
        raise ConfigError("edge_roi", None, reason)
    except ConfigError as exc:
        if exc.key == "edge_roi":
            raise
        raise ConfigError("edge_roi", exc.value, exc.reason) from None
