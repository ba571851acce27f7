"""Eye-to-hand calibration the way users do it today: OpenCV's hand-eye solvers on a board's poses
(pure numpy + OpenCV, no pydrake). The marker-based baseline of ``bench/bench_baseline_hand_eye.py``.

A fixed camera C sees a board B held by the hand H: ``X_WC X_CB_i = X_WH_i X_HB`` for every pose i,
with ``X_WC`` and ``X_HB`` unknown and constant.

- ``cv2.calibrateHandEye`` solves the eye-in-hand problem ``A_i X = X B_i``. For a fixed camera its
  documentation has the robot poses inverted: pass base-to-gripper (``X_HW_i``, the inverse of
  ``X_WH_i``) where it asks for gripper-to-base, the board's pose in the camera ``X_CB_i`` as
  target-to-camera, and it returns camera-to-base, ``X_WC``.
- ``cv2.calibrateRobotWorldHandEye`` solves ``cTw_i wTb = cTg gTb_i``. Matching the fixed-camera
  chain inverted, ``X_BC_i X_CW = X_BH X_HW_i``, its "camera" is the board, its "world" our camera,
  its "base" our world and its "gripper" our hand: pass ``X_BC_i`` (the inverse of the board pose)
  as world-to-camera and ``X_HW_i`` as base-to-gripper; it returns ``X_CW`` (base-to-world) and
  ``X_BH`` (gripper-to-camera).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

# The five solvers of cv2.calibrateHandEye (AX = XB).
HAND_EYE_METHODS = {
    "TSAI": cv2.CALIB_HAND_EYE_TSAI,
    "PARK": cv2.CALIB_HAND_EYE_PARK,
    "HORAUD": cv2.CALIB_HAND_EYE_HORAUD,
    "ANDREFF": cv2.CALIB_HAND_EYE_ANDREFF,
    "DANIILIDIS": cv2.CALIB_HAND_EYE_DANIILIDIS,
}
# The two solvers of cv2.calibrateRobotWorldHandEye (AX = ZB).
ROBOT_WORLD_METHODS = {
    "SHAH": cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH,
    "LI": cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI,
}
# Both solvers need two motions, so three poses.
MIN_POSES = 3


def _poses(name: str, X) -> np.ndarray:
    X = np.asarray(X, float)
    if X.ndim != 3 or X.shape[1:] != (4, 4) or not np.isfinite(X).all():
        raise ValueError(f"{name} must be a finite (n, 4, 4) array of poses, got shape {X.shape}")
    return X


def invert(X: np.ndarray) -> np.ndarray:
    """The inverses of rigid transforms ``X`` (..., 4, 4)."""
    R, p = X[..., :3, :3], X[..., :3, 3]
    out = np.zeros_like(X)
    out[..., :3, :3] = np.swapaxes(R, -1, -2)
    out[..., :3, 3] = -np.einsum("...ji,...j->...i", R, p)
    out[..., 3, 3] = 1.0
    return out


def _matrix(R, t) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = np.asarray(R, float), np.asarray(t, float).ravel()
    return X


def _split(X: np.ndarray) -> tuple[list, list]:
    """OpenCV's lists of rotations (3 x 3) and translations (3 x 1) of poses ``X`` (n, 4, 4)."""
    return [np.ascontiguousarray(x[:3, :3]) for x in X], [x[:3, 3].reshape(3, 1).copy() for x in X]


def _check_pair(X_WH, X_CB) -> tuple[np.ndarray, np.ndarray]:
    X_WH, X_CB = _poses("X_WH", X_WH), _poses("X_CB", X_CB)
    if len(X_WH) != len(X_CB):
        raise ValueError(f"X_WH has {len(X_WH)} poses but X_CB has {len(X_CB)}: they must pair one to one")
    if len(X_WH) < MIN_POSES:
        raise ValueError(f"eye-to-hand needs at least {MIN_POSES} poses, got {len(X_WH)}")
    return X_WH, X_CB


def eye_to_hand(X_WH, X_CB, method: str = "TSAI") -> np.ndarray:
    """``X_WC`` (4 x 4) by ``cv2.calibrateHandEye`` with ``method`` (a key of ``HAND_EYE_METHODS``)
    from the hand poses ``X_WH`` and the board's poses in the camera ``X_CB`` (n, 4, 4 each), the
    robot poses inverted as OpenCV documents for a fixed camera. ValueError for fewer than
    ``MIN_POSES`` poses, shapes that do not pair or an unknown method."""
    X_WH, X_CB = _check_pair(X_WH, X_CB)
    if method not in HAND_EYE_METHODS:
        raise ValueError(f"method must be one of {', '.join(HAND_EYE_METHODS)}, got {method!r}")
    R_base2gripper, t_base2gripper = _split(invert(X_WH))
    R_target2cam, t_target2cam = _split(X_CB)
    R, t = cv2.calibrateHandEye(R_base2gripper, t_base2gripper, R_target2cam, t_target2cam,
                                method=HAND_EYE_METHODS[method])
    return _matrix(R, t)


def robot_world_eye_to_hand(X_WH, X_CB, method: str = "SHAH") -> tuple[np.ndarray, np.ndarray]:
    """``(X_WC, X_HB)`` (4 x 4 each) by ``cv2.calibrateRobotWorldHandEye`` with ``method`` (a key of
    ``ROBOT_WORLD_METHODS``), from the same inputs as ``eye_to_hand`` (mapped as the module says)."""
    X_WH, X_CB = _check_pair(X_WH, X_CB)
    if method not in ROBOT_WORLD_METHODS:
        raise ValueError(f"method must be one of {', '.join(ROBOT_WORLD_METHODS)}, got {method!r}")
    R_world2cam, t_world2cam = _split(invert(X_CB))
    R_base2gripper, t_base2gripper = _split(invert(X_WH))
    R_CW, t_CW, R_BH, t_BH = cv2.calibrateRobotWorldHandEye(
        R_world2cam, t_world2cam, R_base2gripper, t_base2gripper, method=ROBOT_WORLD_METHODS[method])
    return invert(_matrix(R_CW, t_CW)), invert(_matrix(R_BH, t_BH))


def pose_error(X_est: np.ndarray, X_true: np.ndarray) -> tuple[float, float]:
    """``(position m, rotation rad)``: the distance between the two origins and the angle of
    ``R_est^T R_true``; both inf for a non-finite estimate."""
    X_est, X_true = np.asarray(X_est, float), np.asarray(X_true, float)
    if not np.isfinite(X_est).all():
        return math.inf, math.inf
    position = float(np.linalg.norm(X_est[:3, 3] - X_true[:3, 3]))
    cosine = (np.trace(X_est[:3, :3].T @ X_true[:3, :3]) - 1.0) / 2.0
    return position, float(np.arccos(np.clip(cosine, -1.0, 1.0)))
