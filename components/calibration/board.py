"""Calibration boards: where each corner lies on the board (mm), and the board's pattern
(which colour each point of the board has), so that a detector and a renderer mean the
same board.

Board frame: origin at the first inner corner, x along the corner rows (``cols``
corners), y along the columns (``rows`` corners), z = 0 on the board's face, the
camera looks at it from z < 0 (the face normal is -z). Units: mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np

from humanpt.runtime.config import Range

__all__ = ["Chessboard", "CharucoSpec", "charuco_available", "BoardError"]


class BoardError(ValueError):
    """A board that cannot be used (bad size, missing OpenCV module...)."""


@dataclass(frozen=True)
class Chessboard:
    """A chessboard of ``cols`` x ``rows`` INNER corners (OpenCV's ``patternSize``), squares
    of ``square_mm``, surrounded by a white margin of ``margin_squares`` squares.

    The pattern has (cols + 1) x (rows + 1) squares; square (i, j) (i along x from -1,
    j along y from -1) is dark when i + j is even, so the square that touches the first
    inner corner diagonally at the board's origin, (-1, -1), is dark."""

    cols: Annotated[int, Range(2, 100, "corners")] = 9
    rows: Annotated[int, Range(2, 100, "corners")] = 6
    square_mm: Annotated[float, Range(1.0, 1000.0, "mm")] = 25.0
    margin_squares: Annotated[int, Range(1, 10, "squares")] = 1

    def __post_init__(self) -> None:
        if not (2 <= int(self.cols) <= 100 and 2 <= int(self.rows) <= 100):
            raise BoardError(f"chessboard: cols and rows (inner corners) must be 2..100, got {self.cols} x {self.rows}")
        if not (np.isfinite(self.square_mm) and self.square_mm > 0):
            raise BoardError(f"chessboard: square_mm must be > 0, got {self.square_mm}")
        if self.cols == self.rows:
            # A square grid has a 90 deg symmetry: the view's corner order would be ambiguous.
            raise BoardError("chessboard: cols and rows must differ (a square grid has no unique corner order)")

    @property
    def pattern_size(self) -> tuple[int, int]:
        """(cols, rows) of inner corners, OpenCV's ``patternSize``."""
        return (int(self.cols), int(self.rows))

    @property
    def n_corners(self) -> int:
        return int(self.cols) * int(self.rows)

    def object_points_mm(self) -> np.ndarray:
        """(cols * rows, 3) inner corners in the board frame, mm, row by row (x fastest),
        OpenCV's order."""
        j, i = np.mgrid[0:self.rows, 0:self.cols]
        pts = np.zeros((self.n_corners, 3))
        pts[:, 0] = i.ravel() * self.square_mm
        pts[:, 1] = j.ravel() * self.square_mm
        return pts

    def extent_mm(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the whole board incl. its white margin, mm."""
        s = self.square_mm
        m = 1 + int(self.margin_squares)
        return (-m * s, (self.cols - 1 + m) * s, -m * s, (self.rows - 1 + m) * s)

    def reflectance(self, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
        """Reflectance (0 dark .. 1 white) of the board at (x, y) mm (any equal shapes);
        NaN off the board. Dark squares 0.05, white 0.9 (printed paper)."""
        s = self.square_mm
        i = np.floor(np.asarray(x_mm) / s)
        j = np.floor(np.asarray(y_mm) / s)
        in_pattern = (i >= -1) & (i <= self.cols - 1) & (j >= -1) & (j <= self.rows - 1)
        dark = in_pattern & (((i + j).astype(np.int64) % 2) == 0)
        x0, x1, y0, y1 = self.extent_mm()
        on_board = (x_mm >= x0) & (x_mm < x1) & (y_mm >= y0) & (y_mm < y1)
        out = np.where(dark, 0.05, 0.9)
        return np.where(on_board, out, np.nan)

    def cell_id(self, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
        """An integer per square of side ``square_mm`` (the pattern's, the margin's and
        beyond): the reflectance is constant in each (a renderer's area test)."""
        s = self.square_mm
        return (np.floor(np.asarray(x_mm) / s).astype(np.int64) * 100003
                + np.floor(np.asarray(y_mm) / s).astype(np.int64))


@dataclass(frozen=True)
class CharucoSpec:
    """A ChArUco board (OpenCV's ``cv2.aruco.CharucoBoard``): ``squares_x`` x ``squares_y``
    squares of ``square_mm`` with markers of ``marker_mm`` from ``dictionary`` (a
    ``cv2.aruco.DICT_*`` name). Inner corners: (squares_x - 1) x (squares_y - 1)."""

    squares_x: int = 10
    squares_y: int = 7
    square_mm: float = 25.0
    marker_mm: float = 18.0
    dictionary: str = "DICT_4X4_50"

    def build(self):
        """(cv2.aruco.CharucoBoard, cv2.aruco.CharucoDetector); BoardError if this
        OpenCV lacks them."""
        if not charuco_available():
            raise BoardError("ChArUco needs cv2.aruco.CharucoBoard and CharucoDetector (OpenCV >= 4.7); "
                             "this OpenCV has not got them: use --board chessboard")
        import cv2

        if not hasattr(cv2.aruco, self.dictionary):
            raise BoardError(f"charuco: no ArUco dictionary {self.dictionary!r} in cv2.aruco")
        if not 0 < self.marker_mm < self.square_mm:
            raise BoardError(f"charuco: marker_mm must be in (0, square_mm), got {self.marker_mm}")
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        board = cv2.aruco.CharucoBoard((int(self.squares_x), int(self.squares_y)), float(self.square_mm),
                                       float(self.marker_mm), dictionary)
        return board, cv2.aruco.CharucoDetector(board)


def charuco_available() -> bool:
    """Whether the installed OpenCV has the public ChArUco API (CharucoBoard and
    CharucoDetector, OpenCV >= 4.7, also in 5.0)."""
    try:
        import cv2
    except ImportError:
        return False
    aruco = getattr(cv2, "aruco", None)
    return aruco is not None and hasattr(aruco, "CharucoBoard") and hasattr(aruco, "CharucoDetector")
