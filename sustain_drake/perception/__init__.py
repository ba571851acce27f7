"""Perception math: body detection by motion coincidence (paper §3.3, §4.2) and what the hand-eye
loop needs of the images (§4.3).

Pure numpy + OpenCV (no pydrake import):

- :mod:`.optical_flow`: Shi–Tomasi + pyramidal Lucas–Kanade tracker, per-cell visual change ṡ_j,
  back-projection of features to camera-frame points ``p_CP``.
- :mod:`.coincidence`: onset detectors ρ_a, ρ_s, the causal AND of Eq. (27), ε_ij, and the body
  rule (confirming motions and counter-evidence).
- :mod:`.body_features`: the same confirming trials per tracked feature (which corners are body).
- :mod:`.point_refinement`: drift-free 3-D points of tracked features (sub-pixel mark, robust depth).
- :mod:`.charuco`: a ChArUco board's corners, its pose by PnP and from depth points (the
  marker-based baseline).
- :mod:`.camera_motion`: the camera notices its own motion from the static scene (beyond the paper).
- :mod:`.scene_reference`: a still frame of the scene, followed into a later frame, finds a move the
  tracks missed.
- :mod:`.evaluation`: per-cell ground truth from a label image, metrics, likelihood-map pictures.
- :mod:`.synthetic`: synthetic per-cell signals for tests and benchmarks.
"""
