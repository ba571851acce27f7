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
8. Uncertainty, from least squares' covariance ``sigma^2 S[:16, :16]^-1``: the 95 % region
   (``observability.radius_95`` of each error's covariance, to first order) of each estimate within
   the accuracy a dynamic identification is declared at (``accuracy_problem``): the mass within
   ``MASS_ACCURACY`` (0.5 %) of it, the centre of mass within ``COM_ACCURACY`` (1 mm), the rotational
   inertia about the centre of mass within ``INERTIA_ACCURACY`` (10 %, its Frobenius norm, which
   bounds the spectral one) of its largest principal moment, the bias within
   ``BIAS_TORQUE_ACCURACY`` (0.002 N m) and ``BIAS_FORCE_ACCURACY`` (0.05 N). A 1 sd bound declares
   with errors up to twice it; the 95 % region is the error the verdict promises. The centre of
   mass's bound also keeps the observation honest: 1 mm of it is ``m g 1 mm / l`` (0.35 N for 0.9 kg
   and the torque length 0.025 m) in a torque row, within the allowable error of a sensor of 0.05 N
   noise (``coordination``: 100 times its square), where an estimate 10 mm off puts every sample over it.

With these bounds the paper's gap criterion (b) is only what it says, a one-dimensional null space
(``default_criteria``' 10): how well the motion determines the payload is the 95 % region's.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack

from sustain_drake.identification.errors import IdentificationError, real_array, real_number
from sustain_drake.identification.observability import (
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
    radius_95,
    region_95,
)
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria, EigenSolution, Verdict

MIN_ANGULAR_EXCITATION = 0.01  # rad/s^2
# The accuracy a dynamic identification is declared at: its 95 % region within each (issue 26's targets).
MASS_ACCURACY = 0.005  # of the mass
COM_ACCURACY = 0.001  # m
INERTIA_ACCURACY = 0.1  # of the largest principal moment about the centre of mass
BIAS_TORQUE_ACCURACY = 0.002  # N m, each component
BIAS_FORCE_ACCURACY = 0.05  # N, each component
_SCALAR_REGION_95 = region_95(1)  # 1.960: the mass's 95 % radius over its sd

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
    return accuracy_problem(covariance, x[:16])


def payload_regions_95(covariance: np.ndarray, theta: np.ndarray) -> dict[str, float]:
    """The 95 % regions' radii of the dynamic payload's estimates ``theta = [phi; b]`` (16, mass > 0)
    of covariance ``covariance`` (16 x 16), each relative to its accuracy bound (1 is on the bound):
    ``mass``, ``com``, ``inertia`` (of the largest principal moment about the centre of mass; inf when
    that moment is not positive), ``bias_tau``, ``bias_f``. IdentificationError for arrays of other
    shapes, a non-finite entry or a mass that is not positive."""
    covariance = real_array("covariance", covariance, (16, 16))
    theta = real_array("theta", theta, (16,))
    phi, mass = theta[:10], float(theta[0])
    var_mass, C_com, C_inertia = _error_covariances(covariance, phi)
    h = phi[1:4]
    I_Cm = np.zeros((3, 3))
    I_Cm[_SIX] = phi[4:10]
    I_Cm = np.triu(I_Cm) + np.triu(I_Cm, 1).T + (np.outer(h, h) - float(h @ h) * np.eye(3)) / mass
    largest = float(np.linalg.eigvalsh(I_Cm)[-1])
    mass_95 = _SCALAR_REGION_95 * math.sqrt(max(var_mass, 0.0))
    return {"mass": mass_95 / (MASS_ACCURACY * mass), "com": radius_95(C_com) / COM_ACCURACY,
            "inertia": radius_95(C_inertia) / (INERTIA_ACCURACY * largest) if largest > 0.0 else math.inf,
            "bias_tau": radius_95(covariance[10:13, 10:13]) / BIAS_TORQUE_ACCURACY,
            "bias_f": radius_95(covariance[13:16, 13:16]) / BIAS_FORCE_ACCURACY}


def accuracy_problem(covariance: np.ndarray, theta: np.ndarray) -> str | None:
    """None when every 95 % region of ``payload_regions_95`` lies within its accuracy bound, else the
    ``WEAKLY_DETERMINED`` reason with the regions and what to do (the sustainable identifier's verdict
    and RLS's "identified" alike)."""
    regions = payload_regions_95(covariance, theta)
    if max(regions.values()) <= 1.0:
        return None
    advice = ("turn the payload faster about three axes" if regions["inertia"] > 1.0 else
              "tilt the payload more widely")  # fmt: skip
    return (f"{WEAKLY_DETERMINED} (95 % region: mass {100.0 * regions['mass'] * MASS_ACCURACY:.3g} %, centre "
            f"of mass {_mm(regions['com'] * COM_ACCURACY)}, rotational inertia "
            f"{100.0 * regions['inertia'] * INERTIA_ACCURACY:.3g} % of its largest principal moment, bias "
            f"{regions['bias_tau'] * BIAS_TORQUE_ACCURACY:.2g} N m / "
            f"{regions['bias_f'] * BIAS_FORCE_ACCURACY:.2g} N; "
            f"allowed {100 * MASS_ACCURACY:g} %, {_mm(COM_ACCURACY)}, {100 * INERTIA_ACCURACY:g} %, "
            f"{BIAS_TORQUE_ACCURACY:g} N m / {BIAS_FORCE_ACCURACY:g} N): {advice}, take more samples")


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
    var_mass, C_com, C_inertia = _error_covariances(covariance, phi)
    return (math.sqrt(max(var_mass, 0.0)), math.sqrt(max(float(np.trace(C_com)), 0.0)),
            math.sqrt(max(float(np.trace(C_inertia)), 0.0)))


def _error_covariances(covariance: np.ndarray, phi: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The mass's variance, the centre of mass's 3 x 3 covariance and the 6 x 6 covariance of the
    central inertia's error entries ``xx, yy, zz, sqrt(2) xy, sqrt(2) xz, sqrt(2) yz`` (so that its
    trace is the Frobenius norm's expected square), to first order (``dynamic_payload_errors``)."""
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
    J[3:] *= math.sqrt(2.0)  # each product appears twice in the matrix
    return float(C[0, 0]), J_p @ C[:4, :4] @ J_p.T, J @ C @ J.T
