"""The ChArUco calibration board: its description (a TOML file in configs/boards/), OpenCV's board object, its
printable texture, and corner detection in images.

Board frame (OpenCV's): origin at the outer top-left corner of the chessboard, x along the columns, y along the
rows, z into the board; lengths in metres. Chessboard (inner) corner k sits at `corners_m[k]` and is the
ChArUco id k. Texture pixel (i, j) covers board coordinates [j, j + 1) × [i, i + 1) texels from the texture's
origin (the outer corner of its white margin), so pixel centres are at (j + ½, i + ½) texels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pydantic import Field, model_validator

from uwlab.errors import ConfigError
from uwlab.model.data import config_dir, read_toml
from uwlab.model.schema import NonEmptyText, Schema, invalid, parse, quantity
from uwlab.outputs import output_file

DEFAULT_BOARD = "boards/charuco-7x5-40mm.toml"
BLACK_REFLECTANCE = 0.04  # matte black print (assumed)
WHITE_REFLECTANCE = 0.80  # matte white paper (assumed)
REFINE_MAX_HALF_WINDOW = 5
# Squares per side of a printable board; square and marker sides (a size in metres or µm is outside).
SquareCount = quantity(3, 100, "squares", hint="", integer=True)
BoardMm = quantity(0.5, 1000.0, "mm")
MarginMm = quantity(0.0, 1000.0, "mm")


class BoardConfig(Schema):
    """A ChArUco board file (configs/boards/*.toml)."""

    squares: tuple[SquareCount, SquareCount] = Field(description="chessboard squares [columns, rows]")
    square_mm: BoardMm = Field(description="side of a chessboard square, as printed and measured [mm]")
    marker_mm: BoardMm = Field(description="side of an ArUco marker [mm]")
    dictionary: NonEmptyText = Field(description="OpenCV ArUco dictionary, e.g. DICT_5X5_100")
    margin_mm: MarginMm = Field(20.0, description="white border around the squares [mm]")

    @model_validator(mode="after")
    def _consistent(self):
        if self.marker_mm >= self.square_mm:
            raise invalid("marker_mm", self.marker_mm, "must be smaller than square_mm")
        if not (self.dictionary.startswith("DICT_") and hasattr(cv2.aruco, self.dictionary)):
            raise invalid("dictionary", self.dictionary, "must name an OpenCV ArUco dictionary, e.g. DICT_5X5_100")
        needed = (self.squares[0] * self.squares[1]) // 2
        markers = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary)).bytesList.shape[0]
        if markers < needed:
            raise invalid("dictionary", self.dictionary, f"has {markers} markers; the board needs {needed}")
        return self


@dataclass(frozen=True)
class CharucoBoard:
    """squares (columns, rows), square and marker side [m], OpenCV dictionary name, white margin [m]."""

    squares: tuple[int, int]
    square_m: float
    marker_m: float
    dictionary: str
    margin_m: float = 0.02

    @classmethod
    def from_toml(cls, path: str | Path | None = None) -> CharucoBoard:
        """Read a board description (None: configs/boards/charuco-7x5-40mm.toml)."""
        path = Path(path) if path is not None else config_dir() / DEFAULT_BOARD
        return cls.from_dict(read_toml(path, "--board"))

    @classmethod
    def from_dict(cls, raw: dict) -> CharucoBoard:
        """A board from its TOML form (`BoardConfig`, millimetres)."""
        config = parse(BoardConfig, raw, "board")
        return cls(
            config.squares, config.square_mm * 1e-3, config.marker_mm * 1e-3, config.dictionary, config.margin_mm * 1e-3
        )

    def to_dict(self) -> dict:
        """The TOML form (millimetres)."""
        return {
            "squares": list(self.squares),
            "square_mm": self.square_m * 1e3,
            "marker_mm": self.marker_m * 1e3,
            "dictionary": self.dictionary,
            "margin_mm": self.margin_m * 1e3,
        }

    @property
    def size_m(self) -> tuple[float, float]:
        """Chessboard size (x, y) [m], without the margin."""
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    def opencv(self) -> cv2.aruco.CharucoBoard:
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(self.squares, self.square_m, self.marker_m, dictionary)

    @property
    def corners_m(self) -> np.ndarray:
        """Board-frame positions (n, 3) of the chessboard corners, indexed by ChArUco id."""
        return np.asarray(self.opencv().getChessboardCorners(), float)

    @property
    def printed_size_m(self) -> tuple[float, float]:
        """Size (x, y) [m] of the printed board with its margin."""
        return tuple(s + 2 * self.margin_m for s in self.size_m)

    def binary_image(self, texels_per_square: int) -> np.ndarray:
        """The board with its white margin as a black-and-white 8-bit image, `texels_per_square` per square."""
        width, height = (n * texels_per_square for n in self.squares)
        image = self.opencv().generateImage((width, height), marginSize=0, borderBits=1)
        return np.pad(image, int(round(self.margin_m / self.square_m * texels_per_square)), constant_values=255)

    def texture(self, texels_per_m: float) -> tuple[np.ndarray, float, tuple[float, float]]:
        """(reflectance image, texel size [m], board coordinates of the image's outer top-left corner): the
        board with its white margin, black = `BLACK_REFLECTANCE`, white = `WHITE_REFLECTANCE`."""
        texel = 1.0 / texels_per_m
        square_px = self.square_m / texel
        if abs(square_px - round(square_px)) > 1e-6:
            raise ConfigError("texels_per_m", texels_per_m, "must put a whole number of texels in a square")
        image = self.binary_image(int(round(square_px)))
        margin = (image.shape[1] - int(round(square_px)) * self.squares[0]) // 2
        reflectance = BLACK_REFLECTANCE + (WHITE_REFLECTANCE - BLACK_REFLECTANCE) * image.astype(np.float32) / 255
        return reflectance, texel, (-margin * texel, -margin * texel)


@dataclass(frozen=True)
class Detection:
    """ChArUco corners found in one image: ids and pixel coordinates (n, 2)."""

    image: str
    ids: np.ndarray
    pixels: np.ndarray


def detect(board: CharucoBoard, image: np.ndarray, name: str = "") -> Detection:
    """Detect the board's ChArUco corners in an 8-bit image: OpenCV `CharucoDetector`, then `refine_corners`."""
    corners, ids, _, _ = cv2.aruco.CharucoDetector(board.opencv()).detectBoard(image)
    if ids is None or len(ids) == 0:
        return Detection(name, np.zeros(0, int), np.zeros((0, 2)))
    return Detection(name, ids.ravel().astype(int), refine_corners(image, corners.reshape(-1, 2).astype(float)))


def refine_corners(image: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Saddle-point refinement (`cornerSubPix`, Förstner-style gradient orthogonality) with a window of half-size
    a quarter of the distance to the nearest other corner, 2 to `REFINE_MAX_HALF_WINDOW` px: wider than the
    detector's default, so more edge pixels average out noise and aliasing, but inside the corner's own squares.
    On the simulated boards this halves the largest corner errors (0.45 → 0.15 px)."""
    if len(pixels) < 2:
        return pixels
    gaps = np.linalg.norm(pixels[:, None] - pixels[None], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    half = np.clip((gaps.min(axis=1) / 4).astype(int), 2, REFINE_MAX_HALF_WINDOW)
    out = pixels.copy()
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-5)
    for size in np.unique(half):
        rows = half == size
        points = pixels[rows].astype(np.float32).reshape(-1, 1, 2)
        out[rows] = cv2.cornerSubPix(image, points, (int(size), int(size)), (-1, -1), criteria).reshape(-1, 2)
    return out


def write_printable(board: CharucoBoard, path: str | Path, dpi: int) -> Path:
    """Write the board as a PNG whose recorded resolution prints it at its true size; refuses to overwrite."""
    import matplotlib.pyplot as plt

    if not 50 <= dpi <= 2400:
        raise ConfigError("--dpi", dpi, "must be in [50, 2400]")
    if Path(path).suffix.lower() != ".png":
        raise ConfigError("--out", str(path), "must end in .png")
    out = output_file(path, "--out")
    per_square = max(int(round(board.square_m * dpi / 0.0254)), 20)
    try:
        plt.imsave(
            out, board.binary_image(per_square), cmap="gray", vmin=0, vmax=255, dpi=per_square / board.square_m * 0.0254
        )
    except OSError as exc:
        raise ConfigError("--out", str(out), f"cannot write ({exc.strerror})") from None
    return out
