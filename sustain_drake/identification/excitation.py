"""Motion that excites what is unknown (issue 25; the paper's own future work, as Kubus et al. do for
payloads): the identifying motion's next posture is chosen among candidate postures for the
information its samples add to the statistic, per second of motion.

The statistic ``S = sum A_t^T A_t`` (Eq. (4)) holds, in its block over the unknowns (every column
but the homogeneous coordinate's), the information ``M = sum Phi_t^T Phi_t`` of the unknowns'
regressor ``Phi_t``; the directions it leaves small are the least-determined ones. A candidate whose
predicted samples add ``dM`` is worth the D-optimal gain ``log det(M + dM) - log det(M)``:

- computed with the unknowns scaled to a unit diagonal of the information the candidates share, so
  the choice does not depend on the unknowns' units;
- with a ridge of ``RIDGE`` on that unit diagonal, so a direction that no sample has determined yet
  is a large gain, not an infinite one;
- the log-determinant is dominated by the smallest eigenvalues, so the least-determined direction
  is filled first.

Pure numpy: the kinematics of a candidate posture and the regressor of its samples are the
caller's (``payload.posture_information`` for the static payload).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# The ridge on the unit-diagonal information: one part in a million of a well-determined unknown's
# information, far below what one rest's samples add (a direction excited by a rest gains ~ln 1e6).
RIDGE = 1e-6


def _scaled_logdet(M: np.ndarray, scale: np.ndarray) -> float:
    sign, logdet = np.linalg.slogdet(M * np.outer(scale, scale) + RIDGE * np.eye(len(scale)))
    return float(logdet) if sign > 0 else -np.inf


def information_gains(M: np.ndarray, added: Sequence[np.ndarray]) -> np.ndarray:
    """The D-optimal gain of each candidate: ``log det(M + dM_i) - log det(M)`` on the unknowns
    scaled to the unit diagonal of ``M + mean_i dM_i`` (an unknown that nothing informs keeps scale
    1), with the ridge ``RIDGE``. ``M``: the information so far (n x n, symmetric positive
    semi-definite); ``added``: each candidate's ``dM`` (n x n)."""
    M = np.asarray(M, dtype=float)
    if not added:
        return np.zeros(0)
    shared = M + sum(np.asarray(d, dtype=float) for d in added) / len(added)
    diagonal = np.diag(shared)
    scale = np.where(diagonal > 0, 1.0 / np.sqrt(np.where(diagonal > 0, diagonal, 1.0)), 1.0)
    base = _scaled_logdet(M, scale)
    return np.array([_scaled_logdet(M + np.asarray(d, dtype=float), scale) - base for d in added])


def ranked_candidates(M: np.ndarray, added: Sequence[np.ndarray], durations: Sequence[float]) -> np.ndarray:
    """The candidates' indices, the largest gain per second first (``information_gains`` over
    ``durations``, s > 0: the time each one's motion and samples take; ties keep their order).
    ValueError for no candidate, a length mismatch or a duration that is not > 0."""
    durations = np.asarray(durations, dtype=float)
    if len(added) == 0 or durations.shape != (len(added),):
        raise ValueError(f"need one duration per candidate and at least one, got {len(added)} candidates "
                         f"and {durations.size} durations")
    if not np.all(durations > 0):
        raise ValueError("every candidate's duration must be > 0 s")
    rate = information_gains(M, added) / durations
    return np.argsort(-np.where(np.isfinite(rate), rate, -np.inf), kind="stable")


def best_candidate(M: np.ndarray, added: Sequence[np.ndarray], durations: Sequence[float]) -> int:
    """The index of the candidate with the largest gain per second (``ranked_candidates``' first)."""
    return int(ranked_candidates(M, added, durations)[0])
