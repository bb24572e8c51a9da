"""A ChArUco board as ``pincal detect --board`` names it: ``charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT``.

The conventions are OpenCV's (``cv2.aruco.CharucoBoard((cols, rows), square, marker, dictionary)``):
COLS squares along the board's x axis, ROWS along its y axis; the inner chessboard corners are numbered
row by row, ``id = i + (COLS - 1) * j`` for the corner ``(i + 1, j + 1)`` squares from the board's
origin, so corner ``id`` lies at ``((id % (COLS - 1) + 1) * SQUARE, (id // (COLS - 1) + 1) * SQUARE, 0)``
[m] in the board frame. The board frame is OpenCV's: origin at the board's outer corner where
``CharucoBoard.generateImage`` draws its top-left, x along the columns (right in that picture), y
along the rows (down), z into the board.

No numpy or OpenCV here: a spec is parsed and checked before any image is read (and ``pincal detect
--board`` is refused in one argparse line without loading them); :mod:`pincal.measurements.images`
makes the OpenCV board and detects it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from pincal.errors import MeasurementError

__all__ = ["BOARD_FORM", "BOARD_EXAMPLE", "DICTIONARY_SIZES", "CharucoSpec", "parse_board"]

#: The form of ``--board`` and an example, for every message about it.
BOARD_FORM = "charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT"
BOARD_EXAMPLE = "charuco:7x5:0.04:0.03:DICT_5X5_100"

#: OpenCV's predefined ArUco dictionaries (``cv2.aruco.DICT_*``) and how many markers each holds
#: (``getPredefinedDictionary(...).bytesList.shape[0]`` in OpenCV 4.10-4.14; tests/test_detect.py
#: checks them against the installed OpenCV). A board needs ``COLS * ROWS // 2`` distinct markers.
DICTIONARY_SIZES = {
    **{f"DICT_{b}X{b}_{n}": n for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000)},
    "DICT_ARUCO_ORIGINAL": 1024, "DICT_APRILTAG_16h5": 30, "DICT_APRILTAG_25h9": 35,
    "DICT_APRILTAG_36h10": 2320, "DICT_APRILTAG_36h11": 587, "DICT_ARUCO_MIP_36h12": 250,
}

_SPEC = re.compile(r"charuco:(\d+)[xX](\d+):([^:]+):([^:]+):(\w+)")


@dataclass(frozen=True)
class CharucoSpec:
    """A ChArUco board, checked when made.

    Attributes:
        cols: squares along the board's x axis (OpenCV's ``size[0]``), at least 2.
        rows: squares along its y axis (``size[1]``), at least 2.
        square: side of a chessboard square [m].
        marker: side of an ArUco marker [m], smaller than ``square``.
        dictionary: the name of an OpenCV predefined dictionary, e.g. ``DICT_5X5_100``.
    """

    cols: int
    rows: int
    square: float
    marker: float
    dictionary: str

    def __post_init__(self) -> None:
        spec = f"--board {self.text}"
        if self.cols < 2 or self.rows < 2:
            raise MeasurementError(f"{spec}: a ChArUco board has at least 2x2 squares; give COLSxROWS as printed")
        if not 0 < self.marker < self.square:
            raise MeasurementError(f"{spec}: the marker side must be positive and smaller than the square side "
                                   "(metres: SQUARE_M then MARKER_M)")
        if self.square > 2.0:  # a board's square is centimetres; metres above 2 are millimetres given
            raise MeasurementError(f"{spec}: a square of {self.square:g} m looks like millimetres; give metres")
        if self.dictionary not in DICTIONARY_SIZES:
            raise MeasurementError(f"{spec}: unknown dictionary '{self.dictionary}'; OpenCV's predefined "
                                   f"dictionaries are {', '.join(DICTIONARY_SIZES)}")
        if self.n_markers > DICTIONARY_SIZES[self.dictionary]:
            raise MeasurementError(f"{spec}: the board needs {self.n_markers} markers but {self.dictionary} holds "
                                   f"{DICTIONARY_SIZES[self.dictionary]}; check COLSxROWS and the dictionary")

    @property
    def text(self) -> str:
        """The spec as ``--board`` takes it."""
        return f"charuco:{self.cols}x{self.rows}:{self.square:g}:{self.marker:g}:{self.dictionary}"

    @property
    def n_markers(self) -> int:
        """ArUco markers on the board: one in every other square."""
        return self.cols * self.rows // 2

    @property
    def n_corners(self) -> int:
        """Inner chessboard corners, the ids 0 .. n_corners - 1."""
        return (self.cols - 1) * (self.rows - 1)

    def corner_position(self, corner: int) -> tuple[float, float]:
        """Corner ``corner``'s (x, y) in the board frame [m] (z = 0), as OpenCV places it."""
        if not 0 <= corner < self.n_corners:
            raise MeasurementError(f"--board {self.text}: no corner {corner}; ids run 0 to {self.n_corners - 1}")
        i, j = corner % (self.cols - 1), corner // (self.cols - 1)
        return (i + 1) * self.square, (j + 1) * self.square


def parse_board(text: str) -> CharucoSpec:
    """``--board``'s text as a :class:`CharucoSpec`.

    Raises:
        MeasurementError: one line with the expected form and an example, or what is wrong with the board.
    """
    match = _SPEC.fullmatch(text.strip())
    numbers: tuple[float, float] | None = None
    if match:
        try:
            numbers = float(match[3]), float(match[4])
        except ValueError:
            numbers = None
    if match is None or numbers is None:
        raise MeasurementError(f"--board '{text}' is not a board spec; expected {BOARD_FORM} (squares across and "
                               f"down, square and marker sides in metres, an OpenCV dictionary), e.g. {BOARD_EXAMPLE}")
    dictionary = next((name for name in DICTIONARY_SIZES if name.lower() == match[5].lower()), match[5])
    return CharucoSpec(int(match[1]), int(match[2]), numbers[0], numbers[1], dictionary)
