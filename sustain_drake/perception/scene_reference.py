"""The still scene remembered by its image, to find a camera move that the tracks did not follow.
Pure numpy + OpenCV.

The camera-motion detector (``camera_motion``) sees a move through anchors tracked across it. A move
made while the tracks were broken is lost to it: a person walking between the camera and the arm
hides the scene as the head turns, or the anchors thin out below ``min_background`` during the move
(a turn's perspective takes the image's edges off the similarity fit). After such a gap the new
anchors are born in the moved image, and every later frame looks still.

So the detector keeps a *reference*: a still frame's grey image with the still scene's anchors in it
(their mean pixels and 3-D points over the view, ``SceneView``). When the scene is still again after a
gap, each reference anchor is followed from the reference image straight into the current one by
pyramidal Lucas-Kanade (``MAX_LEVEL`` levels: a pan of 0.2 rad, 120-180 px at 640-720 px of 45 deg,
is a few pixels at the top level) and back (forward-backward within ``FB_PX``); the homography that
most followed anchors agree on within ``match_px`` (RANSAC, ``cv2.findHomography``: a turn about the
camera maps the image by one) is the image motion across the gap, and the median distance its
inliers moved is its size; a move must be confirmed by the current anchors followed back into the
reference. Descriptor matching was tried first: from the side of the arm the
still scene's corners are edges and repeated print, whose descriptors are equal at different places
(Hamming distance 0 at 28 px apart), so few matches were mutual; following a point through the
image pyramid uses its neighbourhood, not its own patch alone.

The anchors followed both ways are the static scene's correspondences across the move, as tracks
through it would have given (``camera_motion.SceneTurn``): a point's bearing before and after, and
its 3-D points where an anchor on either side lies within ``NEAR_PX`` of the followed pixel (NaN
without one).

``match_px``: the detector passes its ``move_px``, the smallest displacement it declares; a move's
parallax (the head's pivot is not the camera's centre: a few millimetres over the scene's 1-3 m)
stays well inside it.
"""

from dataclasses import dataclass, field

import cv2
import numpy as np

# Pyramid levels above the image: level L shrinks a displacement 2^L times, so a 0.2 rad pan (174 px
# at 720 x 720) is 5.4 px at level 5, well inside the window.
MAX_LEVEL = 5
WINDOW_PX = 21  # px: Lucas-Kanade window (square) at every level
FB_PX = 1.0  # px: a followed point that does not come back within this is dropped (the tracker's own bound)
NEAR_PX = 1.5  # px: a current anchor this near a followed pixel is the same scene point (its depth is used)
# The fewest followed points that agree on a motion for a verdict: a wrongly followed point lands
# anywhere, within match_px of a given motion with a chance of about pi match_px^2 / (W H) (4e-4 at
# 6 px in 640 x 480), so eight of them agreeing by chance does not happen; the fit itself takes two.
MIN_MATCHES = 8
_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)


@dataclass(frozen=True)
class SceneReference:
    """The still scene at ``time`` (s): the frame's grey image ``gray`` (H x W uint8, not written
    to) and per anchor its pixel ``px`` (K x 2) and 3-D point ``p_CP`` (K x 3, m, camera frame;
    NaN rows without depth)."""

    time: float = 0.0
    gray: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.uint8))
    px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    p_CP: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def __len__(self) -> int:
        return int(self.px.shape[0])


@dataclass(frozen=True)
class ReferenceMatch:
    """The image motion ``H`` (3 x 3 homography, reference pixels -> current ones) that the
    reference anchors followed into the current image agree on, the median distance its inliers
    moved (``moved_px``), and the static scene's correspondences across it: per row a pixel in the
    reference ``px0`` with its point ``q0`` (K x 3, m; NaN rows: none known) and the same scene
    point's pixel now ``px1`` with its point ``q1`` (NaN rows: none known). The rows are the
    reference anchors followed forward, then (after a move) the current anchors followed back that
    agree with ``H`` (one already among the first is not repeated)."""

    H: np.ndarray
    moved_px: float
    px0: np.ndarray
    q0: np.ndarray
    px1: np.ndarray
    q1: np.ndarray

    def __len__(self) -> int:
        return int(self.px0.shape[0])


def match(reference: SceneReference, gray: np.ndarray, px: np.ndarray, p_CP: np.ndarray, match_px: float,
          min_fraction: float) -> ReferenceMatch | None:  # fmt: skip
    """The image motion from ``reference`` to the grey image ``gray`` with the current anchors at
    ``px`` (K x 2) with points ``p_CP`` (K x 3): the homography that at least ``MIN_MATCHES`` of the
    reference anchors followed into ``gray``, and ``min_fraction`` of those followed, agree on
    within ``match_px`` (RANSAC; a camera's turn maps the image by a homography, a similarity only
    approximately: at 0.2 rad two regions' similarities differ by 12 px). When its inliers moved
    ``match_px`` or more (their median; a homography of a few points bends far from them), the
    current anchors followed back into the reference must agree with it as well (as many and as
    large a share): a thing that rested among the reference's anchors and has moved since (a
    person who stood still, then walked) can sway the first set, but the still scene now holds the
    second. None without such agreement."""
    if len(reference) < 3 or reference.gray.shape != np.shape(gray):
        return None
    gray = np.ascontiguousarray(gray, np.uint8)
    px, p_CP = np.asarray(px, float).reshape(-1, 2), np.asarray(p_CP, float).reshape(-1, 3)
    rows, p1 = _followed(reference.gray, gray, reference.px)
    if rows.size < MIN_MATCHES:
        return None
    # Deterministic: OpenCV's RANSAC draws from a fixed-seed generator on each call.
    H, inliers = cv2.findHomography(reference.px[rows], p1, cv2.RANSAC, match_px, maxIters=2000,
                                    confidence=0.995)  # fmt: skip
    if H is None or inliers is None or not np.all(np.isfinite(H)):
        return None
    keep = inliers.ravel().astype(bool)
    if np.count_nonzero(keep) < max(MIN_MATCHES, min_fraction * rows.size):
        return None
    rows, p1 = rows[keep], p1[keep]
    px0, q0, px1, q1 = reference.px[rows], reference.p_CP[rows], p1, _points_near(p1, px, p_CP)
    moved = float(np.median(np.linalg.norm(p1 - px0, axis=1)))
    if moved >= match_px:
        back_rows, back_p0 = _followed(gray, reference.gray, px)
        agree = np.linalg.norm(_mapped(H, back_p0) - px[back_rows], axis=1) <= match_px
        if np.count_nonzero(agree) < max(MIN_MATCHES, min_fraction * back_rows.size):
            return None  # the still scene now does not show that motion
        back_rows, back_p0 = back_rows[agree], back_p0[agree]
        new = np.isnan(_points_near(px[back_rows], px1, np.zeros((px1.shape[0], 3)))[:, 0])
        px0 = np.vstack([px0, back_p0[new]])
        q0 = np.vstack([q0, _points_near(back_p0[new], reference.px, reference.p_CP)])
        px1, q1 = np.vstack([px1, px[back_rows][new]]), np.vstack([q1, p_CP[back_rows][new]])
    return ReferenceMatch(H, moved, px0, q0, px1, q1)


def _followed(gray0: np.ndarray, gray1: np.ndarray, px0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The points ``px0`` (K x 2) of ``gray0`` followed into ``gray1`` by pyramidal Lucas-Kanade
    and back (within ``FB_PX``): the rows of ``px0`` followed and their pixels in ``gray1``."""
    px0 = np.asarray(px0, float).reshape(-1, 2)
    if px0.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros((0, 2))
    p0 = px0.astype(np.float32).reshape(-1, 1, 2)
    win = (WINDOW_PX, WINDOW_PX)
    p1, ok1, _ = cv2.calcOpticalFlowPyrLK(gray0, gray1, p0, None, winSize=win, maxLevel=MAX_LEVEL,
                                          criteria=_CRITERIA)  # fmt: skip
    back, ok2, _ = cv2.calcOpticalFlowPyrLK(gray1, gray0, p1, None, winSize=win, maxLevel=MAX_LEVEL,
                                            criteria=_CRITERIA)  # fmt: skip
    p1, back = p1.reshape(-1, 2).astype(float), back.reshape(-1, 2).astype(float)
    height, width = gray1.shape
    followed = (ok1.ravel().astype(bool) & ok2.ravel().astype(bool)
                & (np.linalg.norm(back - px0, axis=1) <= FB_PX)
                & np.all((p1 >= 0) & (p1 <= [width - 1, height - 1]), axis=1))
    rows = np.flatnonzero(followed)
    return rows, p1[rows]


def _mapped(H: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``points`` (K x 2) mapped by the homography ``H``."""
    moved = points @ H[:2, :2].T + H[:2, 2]
    return moved / (points @ H[2, :2] + H[2, 2])[:, None]


def _points_near(at_px: np.ndarray, px: np.ndarray, p_CP: np.ndarray) -> np.ndarray:
    """Per pixel of ``at_px``, the 3-D point of the anchor at ``px`` within ``NEAR_PX`` of it (the
    nearest), else NaN."""
    out = np.full((at_px.shape[0], 3), np.nan)
    px, p_CP = np.asarray(px, float).reshape(-1, 2), np.asarray(p_CP, float).reshape(-1, 3)
    if px.shape[0] == 0 or at_px.shape[0] == 0:
        return out
    distance = np.linalg.norm(at_px[:, None, :] - px[None, :, :], axis=2)
    nearest = distance.argmin(axis=1)
    near = distance[np.arange(at_px.shape[0]), nearest] <= NEAR_PX
    out[near] = p_CP[nearest[near]]
    return out
