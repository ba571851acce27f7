"""A ChArUco board seen by an RGB-D camera: what a marker-based eye-to-hand calibration measures
per image (pure numpy + OpenCV, no pydrake).

The board frame B is OpenCV's: origin at the outer corner of the first square (the texture's
top-left), x along the columns, y along the rows (down the printed image), z = x cross y into
the board, so the printed face is z = 0 and its outward normal is -z. ChArUco corner ``i`` is at
``board.getChessboardCorners()[i]`` in B (metres). ``models/charuco_board_tool.sdf`` carries this
frame as ``charuco`` on the held board, and ``models/generate_charuco_board.py`` prints the
texture from ``make_board(BOARD)``.

Per image (``measure_board``): the corners found by ``cv2.aruco.CharucoDetector.detectBoard``
(sub-pixel), the board pose ``X_CB`` by ``cv2.solvePnP`` on those pixels, and the corners' 3-D
points from the depth image (the depth where each corner's ray meets the face's plane fitted to a
small window, ``point_refinement.local_depth``, as the marker-free loop reads its points), with a
second board pose fitted rigidly to them (``rigid_fit``, Kabsch).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sustain_drake.perception.optical_flow import PinholeIntrinsics, pinhole_points, to_gray
from sustain_drake.perception.point_refinement import RefinementParams, local_depth


@dataclass(frozen=True)
class CharucoSpec:
    """A ChArUco board's layout: squares across x and down y, their side and the markers' (m),
    and the ArUco dictionary (a ``cv2.aruco.DICT_*`` constant)."""

    squares: tuple[int, int] = (5, 7)
    square_length: float = 0.030  # m
    marker_length: float = 0.022  # m: each marker sits in a white square with 4 mm to spare
    dictionary: int = cv2.aruco.DICT_4X4_50

    @property
    def size(self) -> tuple[float, float]:
        """The squares' extent (m) along B's x and y (the printed margin around them excluded)."""
        return self.squares[0] * self.square_length, self.squares[1] * self.square_length


# The held board of the baseline (models/charuco_board_tool.sdf): 150 x 210 mm, 24 corners.
BOARD = CharucoSpec()
# At least this many corners for a board pose (solvePnP's planar solution needs 4; 6 keeps a
# pose off a short row of corners at the board's edge).
MIN_CORNERS = 6


def make_board(spec: CharucoSpec = BOARD) -> cv2.aruco.CharucoBoard:
    """The OpenCV board of ``spec`` (corner ids row by row, 0 at B's origin side)."""
    dictionary = cv2.aruco.getPredefinedDictionary(spec.dictionary)
    return cv2.aruco.CharucoBoard(spec.squares, spec.square_length, spec.marker_length, dictionary)


def corner_points(spec: CharucoSpec = BOARD) -> np.ndarray:
    """``p_BQ`` (N x 3, m) of every ChArUco corner, by id."""
    return np.asarray(make_board(spec).getChessboardCorners(), float).reshape(-1, 3)


def camera_matrix(intrinsics: PinholeIntrinsics) -> np.ndarray:
    """OpenCV's 3 x 3 camera matrix of pinhole ``intrinsics`` (no distortion)."""
    return np.array([[intrinsics.fx, 0.0, intrinsics.cx], [0.0, intrinsics.fy, intrinsics.cy],
                     [0.0, 0.0, 1.0]])


def pose_matrix(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The 4 x 4 homogeneous transform of rotation ``R`` and translation ``p``."""
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, np.ravel(p)
    return X


class CharucoFinder:
    """Finds a board's corners in colour images (one ``CharucoDetector``, made once)."""

    def __init__(self, spec: CharucoSpec = BOARD):
        self.spec = spec
        self.board = make_board(spec)
        self.p_BQ = corner_points(spec)
        self._detector = cv2.aruco.CharucoDetector(self.board)

    def detect(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(ids, px)``: the ChArUco corners found in ``image`` (RGB, RGBA or grey; H x W [x C]),
        ids ascending (K,) and their sub-pixel pixels (K x 2); empty when no board is found."""
        corners, ids, _, _ = self._detector.detectBoard(to_gray(np.asarray(image)))
        if ids is None or len(ids) == 0:
            return np.zeros(0, int), np.zeros((0, 2))
        ids = np.asarray(ids, int).ravel()
        order = np.argsort(ids)
        return ids[order], np.asarray(corners, float).reshape(-1, 2)[order]


def pnp_pose(p_BQ: np.ndarray, px: np.ndarray, intrinsics: PinholeIntrinsics) -> np.ndarray | None:
    """``X_CB`` (4 x 4) from the corners' board points ``p_BQ`` (K x 3) and pixels ``px`` (K x 2) by
    ``cv2.solvePnP`` (iterative Levenberg-Marquardt from the planar homography's start); None with
    fewer than ``MIN_CORNERS`` corners or when OpenCV finds no pose."""
    if len(px) < MIN_CORNERS:
        return None
    ok, rvec, tvec = cv2.solvePnP(np.asarray(p_BQ, np.float64), np.asarray(px, np.float64).reshape(-1, 1, 2),
                                  camera_matrix(intrinsics), None, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        return None
    return pose_matrix(cv2.Rodrigues(rvec)[0], tvec)


def rigid_fit(p_B: np.ndarray, p_C: np.ndarray) -> np.ndarray | None:
    """``X_CB`` (4 x 4) minimising ``sum |X_CB p_B - p_C|^2`` over rotations and translations (Kabsch /
    Umeyama without scale); None with fewer than 3 points or points on one line."""
    p_B, p_C = np.asarray(p_B, float).reshape(-1, 3), np.asarray(p_C, float).reshape(-1, 3)
    if len(p_B) < 3:
        return None
    mean_B, mean_C = p_B.mean(axis=0), p_C.mean(axis=0)
    U, s, Vt = np.linalg.svd((p_C - mean_C).T @ (p_B - mean_B))
    if s[1] <= 1e-9 * max(s[0], 1e-300):
        return None  # collinear: the turn about that line is free
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return pose_matrix(R, mean_C - R @ mean_B)


@dataclass(frozen=True)
class BoardView:
    """What one image tells of the board: the corners found (``ids``, ``px``), their 3-D points from
    the depth image (``p_CQ``, K x 3 m, NaN rows where the depth gives none) and the board pose from
    the colour image (``X_CB_pnp``) and from the depth points (``X_CB_depth``), each None when not
    measured."""

    ids: np.ndarray
    px: np.ndarray
    p_CQ: np.ndarray
    X_CB_pnp: np.ndarray | None
    X_CB_depth: np.ndarray | None


# The depth of a corner: the loop's own reading (plane through a 5 x 5 window's same-surface pixels).
DEPTH_READING = RefinementParams(depth_plane=True)


def measure_board(finder: CharucoFinder, image: np.ndarray, depth: np.ndarray | None,
                  intrinsics: PinholeIntrinsics) -> BoardView:
    """Detects the board in ``image``, estimates its pose by PnP and, with a ``depth`` image (m,
    H x W), reads its corners' 3-D points and fits the pose to them (``MIN_CORNERS`` at least)."""
    ids, px = finder.detect(image)
    p_CQ = np.full((len(ids), 3), np.nan)
    X_pnp = pnp_pose(finder.p_BQ[ids], px, intrinsics)
    X_depth = None
    if depth is not None and len(ids):
        z = local_depth(np.asarray(depth), px, DEPTH_READING, intrinsics)
        good = np.isfinite(z) & (z > 0)
        p_CQ[good] = pinhole_points(px[good], z[good], intrinsics)
        if good.sum() >= MIN_CORNERS:
            X_depth = rigid_fit(finder.p_BQ[ids[good]], p_CQ[good])
    return BoardView(ids, px, p_CQ, X_pnp, X_depth)
