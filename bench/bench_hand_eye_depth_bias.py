"""How far in front of the rod's axis the depth camera sees the rod (hand_eye.yaml, no depth noise).

A corner tracked on the rod is back-projected with the depth image, which measures the rod's near
surface, not its axis: the 3-D point the identifier gets is biased towards the camera by about the
rod's radius, in a direction that turns with the hand. Prints, for points along the rod axis at a
few instants, the depth image at the point's pixel minus the point's true depth (mm).

    .venv/bin/python bench/bench_hand_eye_depth_bias.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from sustain_drake.station import build_station, camera_info, load_scenario
from sustain_drake.systems.optical_flow_tracker import intrinsics_from_camera_info

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    scenario = load_scenario(ROOT / "diagrams" / "hand_eye.yaml")
    scenario.depth_noise.enabled = False
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    simulator = Simulator(builder.Build())
    K = intrinsics_from_camera_info(camera_info(scenario))
    differences = []
    for t in np.arange(0.5, 10.0, 0.5):
        simulator.AdvanceTo(t + 1e-4)
        context = station.GetMyContextFromRoot(simulator.get_context())
        X_WC = station.GetOutputPort("true_X_WC").Eval(context)
        X_WH = station.GetOutputPort("X_WH").Eval(context)
        p_HP = station.GetOutputPort("true_p_HP").Eval(context)
        depth = station.GetOutputPort("depth_image").Eval(context).data[:, :, 0]
        for s in (0.5, 0.7, 0.9):  # points on the rod axis, as fractions of the way to the tip
            p_C = X_WC.inverse() @ (X_WH @ (s * p_HP))
            u = int(round(K.fx * p_C[0] / p_C[2] + K.cx))
            v = int(round(K.fy * p_C[1] / p_C[2] + K.cy))
            if 0 <= u < K.width and 0 <= v < K.height and np.isfinite(depth[v, u]):
                differences.append(1e3 * (depth[v, u] - p_C[2]))
    d = np.array(differences)
    print(f"{d.size} points: depth image minus true axis depth, median {np.median(d):.1f} mm, "
          f"10-90 % [{np.percentile(d, 10):.1f}, {np.percentile(d, 90):.1f}] mm")


if __name__ == "__main__":
    main()
