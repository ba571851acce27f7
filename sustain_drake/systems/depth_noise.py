"""Range-dependent depth noise, as in real RGB-D sensors (pure numpy).

No "from __future__ import annotations": yaml_load_typed reads DepthNoiseModel's real field types."""


from dataclasses import dataclass

import numpy as np


@dataclass
class DepthNoiseModel:
    """Gaussian depth noise with standard deviation ``a + b (z - z0)^2`` (m) at range z (m),
    as measured for structured-light RGB-D sensors (Nguyen et al. 2012)."""

    a: float = 0.0012  # m: sigma at z0 (Nguyen et al.: 1.2 mm)
    b: float = 0.0019  # 1/m: growth of sigma with (z - z0)^2 (Nguyen et al.: 1.9 mm/m^2)
    z0: float = 0.4  # m: range of the least noise (Nguyen et al.: 0.4 m)

    def __post_init__(self):
        if not (self.a >= 0 and self.b >= 0 and np.isfinite(self.z0)):
            raise ValueError("depth noise needs a >= 0, b >= 0 and a finite z0")

    def sigma(self, z: np.ndarray) -> np.ndarray:
        return self.a + self.b * (z - self.z0) ** 2

    def apply(self, depth: np.ndarray, rng: np.random.Generator, out: np.ndarray | None = None) -> np.ndarray:
        """A noisy copy of ``depth`` (m), written into ``out`` (float32, C-contiguous, the shape of
        ``depth``) when given. Pixels without a return (0 or +inf, Drake's too-near and too-far
        values) are kept; a noisy return stays in front of the camera."""
        z = np.asarray(depth, dtype=np.float32)
        noisy = np.empty(z.shape, np.float32) if out is None else out
        rng.standard_normal(dtype=np.float32, out=noisy)  # the same draws as standard_normal(z.shape)
        # Whole-image float32 arithmetic, in place (no boolean indexing).
        # The clip keeps sigma finite at z = +inf, so inf + noise stays inf (not NaN).
        sigma = np.minimum(z, np.float32(1e3))
        sigma -= np.float32(self.z0)
        np.square(sigma, out=sigma)
        sigma *= np.float32(self.b)
        sigma += np.float32(self.a)
        noisy *= sigma
        noisy += z
        np.maximum(noisy, np.float32(1e-4), out=noisy)
        noisy[z <= 0] = 0.0
        return noisy
