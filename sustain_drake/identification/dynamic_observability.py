"""The dynamic payload's verdict checks (``payload_dynamic``, N = 17; issue 26), pure numpy: the
checks of ``observability`` for the ten inertial parameters and the six bias values, with its
reasons (``ONE_ORIENTATION``, ``NO_ROTATION``, ``ONE_AXIS``, ``UNDETERMINED``,
``WEAKLY_DETERMINED``). In ``observability``'s order:

2. Excitation, independent of the noise, with the bias eliminated from the statistic
   (``P = S_pp - S_pb S_bb^-1 S_bp``: what the samples say about ``phi`` whatever the bias). The
   specific force ``a - g`` must change in K, its RMS change ``sqrt(P_mm / sum |a - g|^2)`` at least
   ``MIN_ROTATION_SPREAD`` of its size (else the mass and the force bias are confounded), and turn
   in K: the first moment's information (times ``l^2``, the torque rows' length squared) per
   ``sum |a - g|^2`` must give an RMS tilt of at least ``MIN_ROTATION_SPREAD`` (else the first
   moment and the torque bias are confounded); either is ``ONE_ORIENTATION``. K must turn with angular
   accelerations about three axes: every direction of the inertia's information at least
   ``MIN_ANGULAR_EXCITATION`` (0.01 rad/s^2) RMS (``NO_ROTATION`` when none is, ``ONE_AXIS`` when
   only one axis is; a turn about one axis leaves the inertia about the other two unseen).
3. The paper's null-space and gap criteria, then (c) a positive mass and a physically valid
   rotational inertia (``payload_dynamic``), then (a).
6. The homogeneous coordinate of the conditioned ``v_N`` is at least ``MIN_HOMOGENEOUS``.
8. Uncertainty, from least squares' covariance ``sigma^2 S[:16, :16]^-1``: 1 sd of the mass within
   ``MAX_MASS_ERROR`` (1 %) of it, of the centre of mass within ``MAX_COM_ERROR`` (10 mm, as for the
   static payload), of the rotational inertia about the centre of mass within ``MAX_INERTIA_ERROR``
   (10 %) of its largest principal moment.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack

from sustain_drake.identification.errors import IdentificationError, real_array, real_number
from sustain_drake.identification.observability import (
    MAX_COM_ERROR,
    MIN_ROTATION_SPREAD,
    NO_ROTATION,
    ONE_AXIS,
    ONE_ORIENTATION,
    UNDETERMINED,
    WEAKLY_DETERMINED,
    _axis_text,
    _guarded,
    _homogeneous_problem,
    _mm,
)
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria, EigenSolution, Verdict

MIN_ANGULAR_EXCITATION = 0.01  # rad/s^2
MAX_MASS_ERROR = 0.01  # of the mass
MAX_INERTIA_ERROR = 0.1  # of the largest principal moment about the centre of mass

# The 3 x 3 inertia matrix's entries in the order of phi[4:10]: xx, yy, zz, xy, xz, yz.
_SIX = ([0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2])


def _bias_eliminated(S: np.ndarray) -> np.ndarray:
    """``P = S_pp - S_pb S_bb^-1 S_bp`` (10 x 10): the information on ``phi`` of the 17 x 17 dynamic
    statistic with the bias unknown (``S_bb`` is diagonal: every sample's bias block is
    ``diag(1/l, 1/l, 1/l, 1, 1, 1)``, ``l`` the torque length)."""
    B = S[10:16, :10]
    return S[:10, :10] - B.T @ (B / np.diagonal(S)[10:16, None])


@_guarded
def _judge_dynamic_payload(criteria: ConvergenceCriteria, S: np.ndarray, weight: float, num_samples: int,
                           eigen: EigenSolution | None, x: np.ndarray, verdict: Verdict) -> Verdict:
    """``verdict`` with the dynamic payload's checks for its 17 x 17 statistic ``S`` of ``weight``
    (``num_samples``) samples, its eigen-solution and the solution ``x = [phi; b; 1]``: what the motion
    excites (2., first), then when (a)-(c) hold the homogeneous coordinate (6.) and the uncertainty of
    mass, centre of mass and rotational inertia (8.). Internal (the identifier's solve)."""
    if eigen is None or num_samples < criteria.min_samples or not weight > 0.0:
        return verdict
    reason = _dynamic_excitation_problem(S, weight)
    if reason is None and verdict.converged:
        reason = (_homogeneous_problem(float(eigen.v_N[16]), "turn and tilt the payload about three axes")
                  or _dynamic_uncertainty_problem(S, weight, x))
    return verdict if reason is None else Verdict(False, reason)


def _dynamic_excitation_problem(S: np.ndarray, weight: float) -> str | None:
    """The specific force ``a - g`` must turn in K (the first moment's information with the bias
    eliminated, per ``sum |a - g|^2``: an RMS tilt of at least ``MIN_ROTATION_SPREAD``), and K must turn
    with angular accelerations about three axes (the inertia's information: every direction at least
    ``MIN_ANGULAR_EXCITATION`` RMS)."""
    P = _bias_eliminated(S)
    length2 = weight / float(S[10, 10])  # l^2: the torque rows' columns of the bias are 1/l
    s2 = float(S[0, 0])  # sum |a - g|^2
    spread = math.sqrt(max(float(P[0, 0]), 0.0) / s2) if s2 > 0.0 else 0.0  # of a - g: the mass's
    lowest, axes = np.linalg.eigh(P[1:4, 1:4])
    tilt = math.sqrt(max(float(lowest[0]), 0.0) * length2 / s2) if s2 > 0.0 else 0.0  # the first moment
    if not min(spread, tilt) >= MIN_ROTATION_SPREAD:
        unseen = ("the mass and the force bias are confounded" if spread < MIN_ROTATION_SPREAD else
                  f"the first moment along {_axis_text(axes[:, 0])} in the sensor frame and the torque bias "
                  "are confounded")  # fmt: skip
        return (f"{ONE_ORIENTATION} (a - g changed by {spread:.2g} of its size RMS and turned {tilt:.2g} "
                f"rad: {unseen}): tilt it about two axes")
    turns = np.sqrt(np.maximum(np.linalg.eigvalsh(P[4:10, 4:10]) * length2 / weight, 0.0))
    if not turns[-1] >= MIN_ANGULAR_EXCITATION:
        return (f"{NO_ROTATION} (angular excitation {turns[-1]:.2g} rad/s^2 RMS: the rotational inertia is "
                "unobservable): turn it, accelerating about three axes")
    if not turns[0] >= MIN_ANGULAR_EXCITATION:
        axis = _axis_text(np.sqrt(np.maximum(np.diagonal(P)[4:7], 0.0)))
        return (f"{ONE_AXIS} ({axis} in the sensor frame; {turns[0]:.2g} rad/s^2 RMS about the others: the "
                "inertia about them is unobservable): turn it about another axis")
    return None


def _dynamic_uncertainty_problem(S: np.ndarray, weight: float, x: np.ndarray) -> str | None:
    covariance = dynamic_payload_covariance(S, weight, x)
    if covariance is None:
        return f"{UNDETERMINED} (the inertial parameters): turn and tilt the payload about three axes"
    mass, (sd_mass, sd_com, sd_inertia) = float(x[0]), dynamic_payload_errors(covariance, x[:10])
    h = x[1:4]
    I_Cm = np.zeros((3, 3))
    I_Cm[_SIX] = x[4:10]
    I_Cm = np.triu(I_Cm) + np.triu(I_Cm, 1).T + (np.outer(h, h) - float(h @ h) * np.eye(3)) / mass
    largest = float(np.linalg.eigvalsh(I_Cm)[-1])
    inertia_ok = sd_inertia <= MAX_INERTIA_ERROR * largest
    if sd_mass <= MAX_MASS_ERROR * mass and sd_com <= MAX_COM_ERROR and inertia_ok:
        return None
    advice = "tilt the payload more widely" if inertia_ok else "turn the payload faster about three axes"
    share = f"{100.0 * sd_inertia / largest:.3g} %" if largest > 0.0 else "inf"
    return (f"{WEAKLY_DETERMINED} (1 sd: mass {100.0 * sd_mass / mass:.3g} %, centre of mass "
            f"{_mm(sd_com)}, rotational inertia {share} of its largest principal moment; allowed "
            f"{100 * MAX_MASS_ERROR:g} %, {_mm(MAX_COM_ERROR)}, {100 * MAX_INERTIA_ERROR:g} %): {advice}, "
            "take more samples")


def dynamic_payload_covariance(S: np.ndarray, weight: float, x: np.ndarray) -> np.ndarray | None:
    """The covariance (16 x 16) of ``[phi; b]`` for the 17 x 17 dynamic payload statistic ``S`` of
    ``weight`` samples and its solution ``x = [phi; b; 1]``: ``sigma^2 S[:16, :16]^-1`` (least squares'
    covariance, the wrench column taken as the noisy one), ``sigma^2 = x^T S x / (6 n - 16)`` the
    residual variance per row (N^2: the torque rows divided by the torque length give every row the
    same noise). None if the parameters are undetermined or
    ``6 weight <= 16``. IdentificationError unless ``S`` is a finite 17 x 17 matrix, ``weight`` a
    number and ``x`` a finite 17-vector."""
    S, x = real_array("S", S, (17, 17)), real_array("x", x, (17,))
    weight = real_number("weight", weight)
    diagonal = np.diagonal(S)[:16]
    if not (6.0 * weight > 16.0 and (diagonal > 0.0).all()):
        return None
    d = 1.0 / np.sqrt(diagonal)  # equilibrated: kg, kg m^2 and N columns alike
    factor, info = lapack.dpotrf(S[:16, :16] * np.outer(d, d))
    if info != 0:
        return None
    inverse, info = lapack.dpotri(factor)
    if info != 0:
        return None
    inverse = np.triu(inverse) + np.triu(inverse, 1).T
    sigma2 = max(float(x @ S @ x), 0.0) / (6.0 * weight - 16.0)
    covariance = sigma2 * inverse * np.outer(d, d)
    return covariance if np.isfinite(covariance).all() else None


def dynamic_payload_errors(covariance: np.ndarray, phi: np.ndarray) -> tuple[float, float, float]:
    """1 sd of the mass (kg), of the centre of mass (m, the RMS of its 3-D error) and of the rotational
    inertia about the centre of mass (kg m^2, the RMS of the 3 x 3 matrix's error: its Frobenius norm)
    for the inertial parameters ``phi = [m; h; I_Ko]`` (m > 0) of covariance ``covariance`` (its first
    10 x 10 block), to first order: ``p = h / m``, ``I_Cm = I_Ko + (h h^T - |h|^2 I_3) / m``.
    IdentificationError unless ``covariance`` is a finite square matrix of at least 10 rows and
    ``phi`` a finite 10-vector."""
    covariance = real_array("covariance", covariance, (None, None))
    phi = real_array("phi", phi, (10,))
    if covariance.shape[0] < 10 or covariance.shape[0] != covariance.shape[1]:
        raise IdentificationError(f"covariance must be a square matrix of >= 10 rows, got {covariance.shape}")
    C, m, h = covariance[:10, :10], float(phi[0]), phi[1:4]
    if not m > 0.0:
        raise IdentificationError(f"phi's mass must be positive, got {m:.6g} kg")
    J_p = np.hstack([-h[:, None] / (m * m), np.eye(3) / m])
    J = np.zeros((6, 10))
    J[:, 4:] = np.eye(6)
    J[:, 0] = -(np.outer(h, h) - float(h @ h) * np.eye(3))[_SIX] / (m * m)
    for i in range(3):
        e = np.eye(3)[i]
        J[:, 1 + i] = (np.outer(e, h) + np.outer(h, e) - 2.0 * h[i] * np.eye(3))[_SIX] / m
    variances = np.diagonal(J @ C @ J.T)
    sd_inertia = math.sqrt(max(float(variances[:3].sum() + 2.0 * variances[3:].sum()), 0.0))
    sd_com = math.sqrt(max(float(np.trace(J_p @ C[:4, :4] @ J_p.T)), 0.0))
    return math.sqrt(max(float(C[0, 0]), 0.0)), sd_com, sd_inertia
