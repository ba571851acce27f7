"""Batch API for recorded data: the sustainable identifiers run over arrays of samples.

The samples stream through the same constant-memory identifiers that the Drake systems use; the
arrays are only kept here to report per-sample residuals.

Every public function raises ``IdentificationError`` (a ``ValueError``, see ``errors``) with a
one-line message for an argument of the wrong type, shape or value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sustain_drake.identification import eye_to_hand, observability, payload
from sustain_drake.identification.errors import (
    ROTATION_TOLERANCE,
    VECTOR3,
    describe,
    instance,
    real_array,
    to_float_array,
)
from sustain_drake.identification.sustainable_identifier import (
    ConvergenceCriteria,
    IdentificationError,
    Verdict,
)


def _check_finite(name: str, a: np.ndarray) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        index = np.argwhere(bad)[0]
        raise IdentificationError(f"{name} is not finite (NaN or inf) at index {tuple(index.tolist())}")


def check_rotations(name: str, R: np.ndarray) -> None:
    """Raises IdentificationError if any ``R[i]`` is not a proper rotation to ROTATION_TOLERANCE
    (each entry of ``R^T R - I``), or if ``R`` is not a finite (n, 3, 3) array."""
    if type(name) is not str:
        raise IdentificationError(f"name must be a string, got {type(name).__name__}")
    R = real_array(name, R, (None, 3, 3))
    err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = np.flatnonzero((err > ROTATION_TOLERANCE) | (det < 0.0))
    if bad.size:
        i = int(bad[0])
        raise IdentificationError(
            f"{name}[{i}] is not a rotation (|R^T R - I| = {err[i]:.2g}, det = {det[i]:.3g})"
        )


def _as_array(name: str, a, shape_tail: tuple[int, ...]) -> np.ndarray:
    try:
        a = to_float_array(name, a, "an array")
    except IdentificationError:
        raise IdentificationError(f"{name} is not a numeric array of real numbers: {describe(a)}") from None
    if a.ndim != 1 + len(shape_tail) or a.shape[1:] != shape_tail:
        want = "(n, " + ", ".join(str(s) for s in shape_tail) + ")"
        raise IdentificationError(f"{name} must have shape {want}, got {a.shape}")
    _check_finite(name, a)
    return a


@dataclass(frozen=True)
class EyeToHandResult:
    """The result of ``calibrate_eye_to_hand``.

    Attributes:
        X_WC: 4 x 4 pose of the camera in the world (the refined estimate).
        p_HP: the point in the hand frame, metres (refined).
        residuals: per-sample distance ``|R_WC p_CP + p_WC - R_WH p_HP - p_WH|``, metres, under the
            refined estimate, in the order of the input.
        rms: root mean square of ``residuals``, metres.
        eigenvalues: ``lambda_1 >= ... >= lambda_16`` of the conditioned statistic.
        gap_ratio: ``lambda_15 / lambda_16``.
        ssd: closeness of the TLS rotation block to a rotation (§3.2).
        expected_rms: ``sqrt(a^2 lambda_16)``, the identification's own error prediction, metres.
        verdict: converged or not, with the reason.
        projected: the TLS estimate projected onto SO(3) (``eye_to_hand.EyeToHandEstimate``).
        refined: its Gauss-Newton refinement (what ``X_WC`` and ``p_HP`` report).
        covariance: Gauss-Newton's covariance (9 x 9) of the refined estimate in ``(omega, p_WC,
            p_HP)``, ``omega`` the camera's turn in its own frame (rad; the truth is
            ``R_WC exp([omega x])``), positions in m (``observability.eye_to_hand_covariance``);
            None without a refined estimate or when it is undetermined.
    """

    X_WC: np.ndarray
    p_HP: np.ndarray
    residuals: np.ndarray
    rms: float
    eigenvalues: np.ndarray
    gap_ratio: float
    ssd: float
    expected_rms: float
    verdict: Verdict
    projected: eye_to_hand.EyeToHandEstimate | None
    refined: eye_to_hand.EyeToHandEstimate | None
    covariance: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        return self.verdict.converged

    @property
    def standard_errors(self) -> tuple[float, float, float] | None:
        """1 sd (the RMS of the 3-D error) of the camera rotation (rad), the camera position and
        ``p_HP`` (m), from ``covariance``; None without it."""
        if self.covariance is None:
            return None
        d = np.diagonal(self.covariance)
        return tuple(math.sqrt(float(d[k:k + 3].sum())) for k in (0, 3, 6))


def eye_to_hand_residuals(X_WC: np.ndarray, p_HP: np.ndarray, p_C: np.ndarray, X_WH: np.ndarray):
    """Per-sample distances ``|R_WC p_CP + p_WC - (R_WH p_HP + p_WH)|`` in metres.
    IdentificationError unless ``X_WC`` is a real 4 x 4 matrix, ``p_HP`` a real 3-vector, ``p_C``
    (n, 3) and ``X_WH`` (n, 4, 4) real arrays (NaN or inf give non-finite distances)."""
    X_WC = real_array("X_WC", X_WC, (4, 4), finite=False)
    p_HP = real_array("p_HP", p_HP, VECTOR3, finite=False)
    p_C = real_array("p_C", p_C, (None, 3), finite=False)
    X_WH = real_array("X_WH", X_WH, (None, 4, 4), finite=False)
    if len(p_C) != len(X_WH):
        raise IdentificationError(
            f"p_C has {len(p_C)} samples but X_WH has {len(X_WH)}: they must pair one to one"
        )
    p_W_cam = p_C @ X_WC[:3, :3].T + X_WC[:3, 3]
    p_W_hand = np.einsum("nij,j->ni", X_WH[:, :3, :3], p_HP) + X_WH[:, :3, 3]
    return np.linalg.norm(p_W_cam - p_W_hand, axis=1)


def calibrate_eye_to_hand(p_C, X_WH, criteria: ConvergenceCriteria | None = None) -> EyeToHandResult:
    """Eye-to-hand calibration from recorded data (paper §3.4, with conditioning and refinement).

    Args:
        p_C: (n, 3) positions of one point fixed on the hand (or held tool), measured in the
            camera frame C, metres.
        X_WH: (n, 4, 4) poses of the hand frame H in the world W (forward kinematics), metres.
        criteria: convergence criteria (``eye_to_hand.default_criteria()`` if None).

    Returns:
        An ``EyeToHandResult``. Degenerate data (too few samples, pure translation, ...) is not an
        error: the verdict says "not converged" and why.

    Raises:
        IdentificationError (a ValueError): wrong types or shapes, mismatched lengths, NaN/inf, a
            pose whose rotation block is not a rotation, or ``criteria`` not a ConvergenceCriteria.
    """
    instance("criteria", criteria, ConvergenceCriteria, "a ConvergenceCriteria or None", optional=True)
    p_C = _as_array("p_C", p_C, (3,))
    X_WH = _as_array("X_WH", X_WH, (4, 4))
    if len(p_C) != len(X_WH):
        raise IdentificationError(
            f"p_C has {len(p_C)} samples but X_WH has {len(X_WH)}: they must pair one to one"
        )
    if not np.allclose(X_WH[:, 3, :], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        i = int(np.flatnonzero(np.abs(X_WH[:, 3, :] - [0, 0, 0, 1]).max(axis=1) > 1e-9)[0])
        raise IdentificationError(f"X_WH[{i}] is not a homogeneous transform: last row is not 0 0 0 1")
    check_rotations("X_WH", X_WH[:, :3, :3])

    identifier = eye_to_hand.EyeToHandIdentifier(criteria=criteria)
    for c, X in zip(p_C, X_WH, strict=True):
        identifier.add(c, X[:3, :3], X[:3, 3])
    solution = identifier.solve(refine_estimate=True)
    estimate = solution.estimate
    if estimate is None:
        X_WC = np.eye(4)
        p_HP = np.zeros(3)
        residuals = np.full(len(p_C), math.inf)
    else:
        X_WC = estimate.X_WC
        p_HP = estimate.p_HP
        residuals = eye_to_hand_residuals(X_WC, p_HP, p_C, X_WH)
    rms = float(np.sqrt(np.mean(residuals**2))) if len(residuals) else math.inf
    covariance = (None if solution.refined is None
                  else observability.eye_to_hand_covariance(identifier.core.S, solution.refined.R_WC))
    return EyeToHandResult(X_WC=X_WC, p_HP=p_HP, residuals=residuals, rms=rms, ssd=solution.ssd,
                           projected=solution.projected, refined=solution.refined, covariance=covariance,
                           **_statistics(solution))  # fmt: skip


@dataclass(frozen=True)
class PayloadResult:
    """The result of ``identify_payload``.

    Attributes:
        mass: kg.
        p_KCm: centre of mass in the sensor frame K, metres.
        force_residuals: per-sample ``|R_WK f_K + m g_W|``, N.
        torque_residuals: per-sample ``|tau_K - p_KCm x f_K|``, N m.
        eigenvalues: ``lambda_1 >= ... >= lambda_5`` of the conditioned statistic.
        gap_ratio: ``lambda_4 / lambda_5``.
        expected_rms: ``sqrt(a^2 lambda_5)`` (m/s^2 and N m rows together).
        verdict: converged or not, with the reason.
        covariance: the covariance (4 x 4) of ``(mass, p_KCm)`` in kg and m
            (``observability.payload_covariance``); None without a positive mass.
    """

    mass: float
    p_KCm: np.ndarray
    force_residuals: np.ndarray
    torque_residuals: np.ndarray
    eigenvalues: np.ndarray
    gap_ratio: float
    expected_rms: float
    verdict: Verdict
    covariance: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        return self.verdict.converged


def identify_payload(
    wrench_K, R_WK, gravity_W=payload.STANDARD_GRAVITY_W, criteria: ConvergenceCriteria | None = None
) -> PayloadResult:
    """Mass and centre of mass of the outboard payload from quasi-static F/T samples (§4.4).

    Args:
        wrench_K: (n, 6) wrenches ``[tau_x, tau_y, tau_z, f_x, f_y, f_z]`` in N m and N, applied by
            the sensor on the payload, in the sensor frame K (see ``payload`` for the convention).
        R_WK: (n, 3, 3) orientations of the sensor frame in the world.
        gravity_W: gravity in the world, m/s^2.
        criteria: convergence criteria (``payload.default_criteria()`` if None).

    Raises:
        IdentificationError (a ValueError): wrong types or shapes, mismatched lengths, NaN/inf, an
            orientation that is not a rotation, ``gravity_W`` not a finite non-zero 3-vector or
            ``criteria`` not a ConvergenceCriteria.
    """
    instance("criteria", criteria, ConvergenceCriteria, "a ConvergenceCriteria or None", optional=True)
    wrench_K = _as_array("wrench_K", wrench_K, (6,))
    R_WK = _as_array("R_WK", R_WK, (3, 3))
    if len(wrench_K) != len(R_WK):
        raise IdentificationError(
            f"wrench_K has {len(wrench_K)} samples but R_WK has {len(R_WK)}: they must pair one to one"
        )
    check_rotations("R_WK", R_WK)
    identifier = payload.PayloadIdentifier(gravity_W=gravity_W, criteria=criteria)
    for w, R in zip(wrench_K, R_WK, strict=True):
        identifier.add(w, R)
    solution = identifier.solve()
    tau, f = wrench_K[:, 0:3], wrench_K[:, 3:6]
    f_W = np.einsum("nij,nj->ni", R_WK, f)
    force_res = np.linalg.norm(f_W + solution.mass * identifier.g_W, axis=1)
    torque_res = np.linalg.norm(tau - np.cross(solution.p_KCm, f), axis=1)
    covariance = observability.payload_covariance(identifier.core.S, identifier.core.weight, solution.x,
                                                  identifier.g_W)  # fmt: skip
    return PayloadResult(mass=solution.mass, p_KCm=solution.p_KCm, force_residuals=force_res,
                         torque_residuals=torque_res, covariance=covariance, **_statistics(solution))


def _statistics(solution) -> dict:
    """What every batch result reports of its identification: the eigenvalues of C, the gap
    ``lambda_{N-1} / lambda_N`` (1 without an eigen-decomposition), the expected RMS error and the
    verdict."""
    gap = solution.eigen.gap_ratio if solution.eigen is not None else 1.0
    return {"eigenvalues": solution.eigenvalues, "gap_ratio": gap, "expected_rms": solution.expected_rms,
            "verdict": solution.verdict}
