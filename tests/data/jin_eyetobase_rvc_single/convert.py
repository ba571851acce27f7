"""Converts the Jin et al. eye-to-base single-marker data set to sustain_drake's CSV formats.

Run from the repository root (needs the original files beside the repository, in
``../shared/data/jin_eyetobase_rvc_single``)::

    .venv/bin/python tests/data/jin_eyetobase_rvc_single/convert.py

Millimetres become metres; ``x y z roll pitch yaw`` flange poses become ``x,y,z,qw,qx,qy,qz``
(through rotation matrices: pitch is near -pi/2, so angles are never averaged or compared). Each
point gets its own ``x,y,z`` file (row i = sample i), and ``all_points.csv`` holds the three in the
``sample,point,x,y,z`` format (points ``corner``, ``aruco10``, ``aruco14``) for the joint fit.
"""

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from sustain_drake.recorded_data import write_point_tracks_csv, write_points_csv, write_poses_csv

HERE = Path(__file__).resolve().parent
SOURCE = HERE.parents[2].parent / "shared" / "data" / "jin_eyetobase_rvc_single"


def main():
    tcp = np.loadtxt(SOURCE / "robot" / "tcpEx.txt")
    n = len(tcp)
    X_WH = np.tile(np.eye(4), (n, 1, 1))
    X_WH[:, :3, 3] = tcp[:, 0:3] / 1000.0
    X_WH[:, :3, :3] = Rotation.from_euler("xyz", tcp[:, 3:6]).as_matrix()
    corner = np.array(
        [np.loadtxt(SOURCE / "pointUndistort" / f"{i}_undistort.txt")[0, 1:4] for i in range(1, n + 1)]
    )
    codes = {10: [], 14: []}
    for i in range(1, n + 1):
        for row in np.loadtxt(SOURCE / "pointCode" / f"{i}_codexyz.txt"):
            codes[int(row[0])].append(row[1:4])
    (HERE / "poses.csv").write_text(write_poses_csv(X_WH))
    (HERE / "corner_points.csv").write_text(write_points_csv(corner / 1000.0))
    every = {"corner": (np.arange(n), corner / 1000.0)}
    for code, points in codes.items():
        assert len(points) == n, f"code {code}: {len(points)} rows"
        (HERE / f"aruco{code}_points.csv").write_text(write_points_csv(np.array(points) / 1000.0))
        every[f"aruco{code}"] = (np.arange(n), np.array(points) / 1000.0)
    (HERE / "all_points.csv").write_text(write_point_tracks_csv(every))


if __name__ == "__main__":
    main()
