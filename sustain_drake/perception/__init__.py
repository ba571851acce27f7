"""Perception math for body detection by motion coincidence (paper §3.3, §4.2).

Pure numpy + OpenCV (no pydrake import):

- :mod:`.optical_flow`: Shi–Tomasi + pyramidal Lucas–Kanade tracker, per-cell visual change ṡ_j,
  back-projection of features to camera-frame points ``p_CP``.
- :mod:`.coincidence`: onset detectors ρ_a, ρ_s, the causal AND of Eq. (27), ε_ij, and the body
  rule (confirming motions and counter-evidence).
- :mod:`.body_features`: the same confirming trials per tracked feature (which corners are body).
- :mod:`.evaluation`: per-cell ground truth from a label image, metrics, likelihood-map pictures.
- :mod:`.synthetic`: synthetic per-cell signals for tests and benchmarks.
"""
