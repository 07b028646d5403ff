"""Corners of a chessboard or ChArUco target in photographs (OpenCV), each with an id that names
the same physical corner in every view.

**Board.** ``cols x rows`` inner corners (where four squares meet), as OpenCV's pattern size;
squares ``square`` [mm]. Corner id ``k = row * cols + col`` lies at ``X = col * square``,
``Y = row * square`` on the board: id 0 at a corner of the grid, ids growing along the rows.

**Chessboard.** ``cv2.findChessboardCornersSB`` (the sector-based detector) finds the whole
grid or nothing: a partial board is not found; ``cv2.cornerSubPix`` refines each corner.
OpenCV may start its list at any corner of the grid; the list is put in the board's order in
two steps:

1. *handedness*: a board is seen from its printed side, so ``+X`` then ``+Y`` turn clockwise
   in the image (``u`` right, ``v`` down); a list that turns the other way is mirrored back;
2. *which corner is id 0*: the first inner square (between ids 0, 1, cols, cols + 1) is the
   dark one. Turning the board by 180° changes the colour of that square when ``cols + rows``
   is odd, so on such a board (and not square) the colours decide, in every view. A board with
   ``cols + rows`` even, or a square one, looks the same turned by 180° (or 90°): no image can
   tell its corners apart, and id 0 is then the candidate corner nearest the image's top-left
   (smallest ``u + v``). The calibration is unaffected (the grid maps onto itself), but an id
   then names the same physical corner only while the board is turned less than 90° between
   views; :attr:`Detection.by_colour` says which rule was used.

**ChArUco.** ``cv2.aruco.CharucoDetector``: each corner's id comes from the markers around
it, so ids are physical and a partly seen board keeps the corners it shows, with their ids.
The board is ``(cols + 1) x (rows + 1)`` squares of ``square`` [mm] with markers of ``marker``
[mm] from the dictionary ``charuco`` (an OpenCV name such as ``DICT_5X5_100``).

Pixels follow OpenCV: ``u`` right, ``v`` down, ``(0, 0)`` the centre of the top-left pixel.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from montecarlo.errors import InputError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

MIN_CORNERS = 4
"""Fewest corners kept in a view (a homography)."""


def cv2_module() -> Any:
    """OpenCV, or an InputError saying how to install it."""
    try:
        import cv2
    except ImportError:
        raise InputError("camera images need OpenCV: pip install 'montecarlo[camera]' "
                         "(opencv-python-headless)") from None
    return cv2


@dataclass(frozen=True)
class Board:
    """A planar target: ``cols x rows`` inner corners, squares of ``square`` [mm]; a ChArUco
    board when ``charuco`` names a dictionary (markers of ``marker`` [mm])."""

    cols: int
    rows: int
    square: float
    charuco: str | None = None
    marker: float | None = None

    @property
    def n(self) -> int:
        return self.cols * self.rows

    @property
    def symmetric(self) -> bool:
        """A chessboard that looks the same turned by 180° (or 90°): its corner ids are set by
        the image, not the board."""
        return self.charuco is None and ((self.cols + self.rows) % 2 == 0
                                         or self.cols == self.rows)

    def model_points(self) -> FloatArray:
        """(n, 2) board coordinates X, Y of ids 0..n-1 [mm]."""
        row, col = np.divmod(np.arange(self.n), self.cols)
        return np.column_stack([col, row]).astype(float) * self.square

    def describe(self) -> str:
        kind = f"ChArUco ({self.charuco})" if self.charuco else "chessboard"
        return f"{self.cols}x{self.rows} {kind} (inner corners, squares {self.square:g} mm)"


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` -> (9, 6): inner corners across and down, each at least 2."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", text)
    if not m or min(int(m.group(1)), int(m.group(2))) < 2:
        raise ValueError(f"{text!r} is not COLSxROWS inner corners (e.g. 9x6, each >= 2)")
    return int(m.group(1)), int(m.group(2))


def view_label(path: str | Path) -> str:
    """A view's name in the CSV files and figures: the image file's name without suffix."""
    return Path(path).stem


@dataclass(frozen=True)
class Detection:
    """The corners found in one image: ``ids`` (k,) and ``pixels`` (k, 2) [px], sorted by id;
    ``by_colour``: id 0 was told by the board's colours (or ChArUco markers), not by the
    image's top-left."""

    path: Path
    ids: IntArray
    pixels: FloatArray
    by_colour: bool


def read_grey(path: str | Path) -> NDArray[np.uint8]:
    """An image file as 8-bit grey; InputError naming the file if it cannot be read."""
    cv2 = cv2_module()
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such image file")
    data = np.fromfile(path, dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None
    if image is None:
        raise InputError(f"{path}: not an image OpenCV can read")
    return image


def read_images(paths: list[str | Path]) -> list[NDArray[np.uint8]]:
    """Every image, all of one size; InputError naming the first unreadable one or the first
    whose size differs from the first image's."""
    if not paths:
        raise InputError("no images given")
    images = []
    for path in paths:
        image = read_grey(path)
        if images and image.shape != images[0].shape:
            h, w = images[0].shape
            raise InputError(f"{path}: {image.shape[1]}x{image.shape[0]} px, but {paths[0]} is "
                             f"{w}x{h} px (one camera, one image size)")
        images.append(image)
    return images


def _square_mean(image: NDArray[np.uint8], quad: FloatArray) -> float:
    """Mean grey level inside a quadrilateral of corner positions (shrunk to its middle half,
    clear of the blurred edges)."""
    cv2 = cv2_module()
    centre = quad.mean(axis=0)
    inner = centre + 0.5 * (quad - centre)
    mask = np.zeros(image.shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(inner * 16).astype(np.int32), 1, cv2.LINE_8, 4)
    if not mask.any():  # a tiny square: its centre pixel
        u, v = np.clip(np.round(centre).astype(int), 0, np.array(image.shape[::-1]) - 1)
        return float(image[v, u])
    return float(image[mask.astype(bool)].mean())


def _first_square(grid: FloatArray) -> FloatArray:
    return np.array([grid[0, 0], grid[0, 1], grid[1, 1], grid[1, 0]])


def order_grid(image: NDArray[np.uint8], grid: FloatArray, board: Board) -> tuple[FloatArray,
                                                                                   bool]:
    """The (rows, cols, 2) grid of corners as OpenCV listed them, put in the board's order
    (module docstring); and whether the board's colours decided id 0."""
    along, down = grid[0, 1] - grid[0, 0], grid[1, 0] - grid[0, 0]
    if along[0] * down[1] - along[1] * down[0] < 0:  # mirrored: +X, +Y anticlockwise
        grid = grid[:, ::-1] if board.cols != board.rows else grid.transpose(1, 0, 2)
    turns = (0, 1, 2, 3) if board.cols == board.rows else (0, 2)
    candidates = [np.rot90(grid, k) for k in turns]
    # does turning the board by k * 90° change the colour of the first inner square?
    flips = np.array([(board.cols + board.rows) % 2 == 1 if k == 2 else
                      (k % 2 == 1 and board.cols % 2 == 1) for k in turns])
    by_colour = False
    if flips.any():
        means = np.array([_square_mean(image, _first_square(g)) for g in candidates])
        dark = flips if means[flips].mean() < means[~flips].mean() else ~flips
        candidates = [g for g, d in zip(candidates, dark, strict=True) if d]
        by_colour = len(candidates) == 1
    best = min(candidates, key=lambda g: float(g[0, 0, 0] + g[0, 0, 1]))
    return best, by_colour


def find_chessboard(image: NDArray[np.uint8], board: Board) -> tuple[IntArray, FloatArray,
                                                                     bool] | None:
    """Ids, pixels [px] and ``by_colour`` of a whole chessboard in ``image``, or None.

    Found by ``cv2.findChessboardCornersSB``, each corner then refined by ``cv2.cornerSubPix``
    in a window a quarter of the shortest corner spacing wide on each side (2 to 10 px)."""
    cv2 = cv2_module()
    flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    found, corners = cv2.findChessboardCornersSB(image, (board.cols, board.rows), flags=flags)
    if not found:
        return None
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = min(np.hypot(*np.diff(grid, axis=a).reshape(-1, 2).T).min() for a in (0, 1))
    half = int(np.clip(spacing / 4, 2, 10))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    refined = cv2.cornerSubPix(image, corners.copy(), (half, half), (-1, -1), criteria)
    grid = refined.reshape(board.rows, board.cols, 2).astype(float)
    ordered, by_colour = order_grid(image, grid, board)
    return np.arange(board.n), ordered.reshape(-1, 2), by_colour


def charuco_board(board: Board) -> Any:
    """The OpenCV ChArUco board of ``board``; InputError for an unknown dictionary."""
    cv2 = cv2_module()
    name = str(board.charuco)
    code = getattr(cv2.aruco, name, None)
    if not name.startswith("DICT_") or not isinstance(code, int):
        known = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
        raise InputError(f"--charuco: {name!r} is not an OpenCV ArUco dictionary (e.g. "
                         f"{', '.join(known[:4])}, ...)")
    dictionary = cv2.aruco.getPredefinedDictionary(code)
    size = (board.cols + 1, board.rows + 1)
    needed = size[0] * size[1] // 2
    if needed > dictionary.bytesList.shape[0]:
        raise InputError(f"--charuco: {name} holds {dictionary.bytesList.shape[0]} markers, a "
                         f"{size[0]}x{size[1]}-square board needs {needed}")
    return cv2.aruco.CharucoBoard(size, board.square, float(board.marker or 0.0), dictionary)


def charuco_model_points(board: Board) -> FloatArray:
    """(n, 2) board coordinates of the ChArUco corner ids 0..n-1 [mm], id 0 at the origin."""
    xyz = np.asarray(charuco_board(board).getChessboardCorners(), float).reshape(-1, 3)
    return xyz[:, :2] - xyz[0, :2]


def find_charuco(image: NDArray[np.uint8], board: Board, detector: Any) -> tuple[
        IntArray, FloatArray, bool] | None:
    """Ids and pixels [px] of the ChArUco corners seen in ``image`` (a partial board keeps
    its ids), or None when fewer than :data:`MIN_CORNERS`, or all on one line of the grid."""
    corners, ids, _, _ = detector.detectBoard(image)
    if ids is None or len(ids) < MIN_CORNERS:
        return None
    ids = ids.reshape(-1).astype(np.int64)
    order = np.argsort(ids)
    ids, pixels = ids[order], corners.reshape(-1, 2).astype(float)[order]
    row, col = np.divmod(ids, board.cols)
    if len(set(row)) < 2 or len(set(col)) < 2:
        return None
    return ids, pixels, True


def detect(paths: list[str | Path], board: Board) -> tuple[list[Detection], list[Path],
                                                            tuple[int, int]]:
    """The board in every image: the detections (in the order given), the images where it was
    not found, and the image size (width, height) [px].

    Raises
    ------
    InputError
        No images, an image that cannot be read, images of different sizes, an unknown ChArUco
        dictionary.
    """
    images = read_images(paths)
    detector = None
    if board.charuco:
        cv2 = cv2_module()
        detector = cv2.aruco.CharucoDetector(charuco_board(board))
    found, missing = [], []
    for path, image in zip(paths, images, strict=True):
        hit = find_charuco(image, board, detector) if detector is not None \
            else find_chessboard(image, board)
        if hit is None:
            missing.append(Path(path))
        else:
            found.append(Detection(Path(path), *hit))
    h, w = images[0].shape
    return found, missing, (w, h)
