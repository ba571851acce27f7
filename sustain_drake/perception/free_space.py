"""Free space along a ray (beyond the paper): does the depth image see through a point?

The paper checks its model with one tracked point (Eq. (2)'s ``s_t``), so the check stops when
that point's track ends, as it does when the tool slips: the mark moves fast and turns, and its
track is lost in the slip itself. A depth camera can still check the model without any track:
where the model puts a point of the tool, the camera must see a surface at that depth or in
front of it (another face of the tool, an occluder). A surface clearly *behind* it means the
camera sees through where the tool should be: the tool is not there.
"""

from __future__ import annotations

import math

import numpy as np

from sustain_drake.perception.optical_flow import PinholeIntrinsics, depth_array


def depth_gap(depth: np.ndarray, intrinsics: PinholeIntrinsics, p_CP: np.ndarray, radius: float) -> float:
    """How far behind the point ``p_CP`` (camera frame C, m) the camera sees a surface: the
    smallest depth in a window of ``radius`` (m, at the point's depth) around the point's pixel,
    minus the point's depth, m.

    Positive: everything around the point's pixel is behind it, so there is nothing at the point
    (the smallest of the window, so that a model off by a few millimetres near a silhouette still
    finds the surface it is on). Zero or negative: a surface at or in front of the point (the point
    itself, or anything hiding it), which says nothing against it. NaN when it cannot be judged: the
    point behind the camera, its window not wholly inside the image, or no finite depth in it.
    Depth pixels follow Drake's ``ImageDepth32F``: 0 is too close (in front), +inf too far
    (behind), NaN unknown (ignored).
    """
    d = depth_array(depth, intrinsics)
    if not radius > 0:
        raise ValueError(f"radius must be positive, got {radius}")
    x, y, z = (float(v) for v in np.asarray(p_CP, dtype=float).ravel()[:3])
    if not (z > 0 and math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return math.nan
    u, v = intrinsics.fx * x / z + intrinsics.cx, intrinsics.fy * y / z + intrinsics.cy
    half_u, half_v = math.ceil(intrinsics.fx * radius / z), math.ceil(intrinsics.fy * radius / z)
    u0, v0 = round(u) - half_u, round(v) - half_v
    u1, v1 = round(u) + half_u + 1, round(v) + half_v + 1
    if u0 < 0 or v0 < 0 or u1 > d.shape[1] or v1 > d.shape[0]:
        return math.nan  # part of the window unseen: whatever is there may be the surface
    window = d[v0:v1, u0:u1]
    seen = window[~np.isnan(window)]
    if seen.size == 0:
        return math.nan
    return float(np.min(seen)) - z
