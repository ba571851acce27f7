"""Dynamic payload identification (issue 26): the Newton-Euler regressor against Drake's own inverse
dynamics, exact recovery of the ten inertial parameters and the bias, honest verdicts on degenerate
motion, the RLS baseline and the encoder filter."""

import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import MultibodyForces_, RotationalInertia, SpatialInertia
from scipy.spatial.transform import Rotation

from sustain_drake.identification import IdentificationError, observability
from sustain_drake.identification import dynamic_observability as dyn_obs
from sustain_drake.identification import payload_dynamic as pd
from sustain_drake.identification.differentiation import (
    joint_derivatives,
    noise_gains,
    savitzky_golay_weights,
)
from sustain_drake.identification.dynamic_observability import (
    dynamic_payload_covariance,
    dynamic_payload_errors,
)
from sustain_drake.identification.rls import DynamicPayloadRLS, RecursiveLeastSquares
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria
from sustain_drake.loops.identify_observe import CoordinationConfig
from sustain_drake.loops.payload import KinestheticConfig, payload_formulation

G_W = np.array([0.0, 0.0, -9.81])
MASS, P_KCM = 0.9, np.array([0.012, -0.02, 0.09])
_R = Rotation.from_euler("xyz", [0.3, -0.5, 1.1]).as_matrix()
I_CM = _R @ np.diag([0.0034, 0.0047, 0.0058]) @ _R.T
PHI = pd.inertial_parameters(MASS, P_KCM, I_CM)
BIAS = np.array([0.015, -0.02, 0.01, 0.4, -0.3, 0.5])
NOISE = np.array([5e-4] * 3 + [0.02] * 3)  # an ATI Mini40: N m, then N


def random_inertia(rng) -> tuple[float, np.ndarray, np.ndarray]:
    """A random rigid body: mass, centre of mass, and a physically valid central inertia."""
    moments = rng.uniform(0.5, 1.0, 3) * 10.0 ** rng.uniform(-3.5, -1.5)
    R = Rotation.random(random_state=rng).as_matrix()
    return float(rng.uniform(0.1, 5.0)), rng.normal(0.0, 0.1, 3), R @ np.diag(moments) @ R.T


def rich_stream(n, rng, *, axes=(1, 1, 1), rotate=True, tilt=True):
    """``n`` kinematics samples: turns with angular accelerations about ``axes`` (if ``rotate``),
    accelerations, and gravity in every direction of K (else one fixed direction, if not ``tilt``)."""
    orientations = Rotation.random(n, random_state=rng).as_matrix()
    fixed = Rotation.from_euler("xyz", [0.2, -0.4, 0.7]).as_matrix()
    samples = []
    for R in orientations:
        R_WK = R if tilt else fixed
        w = rng.normal(0.0, 1.0) * np.asarray(axes, float) if not all(axes) else rng.normal(0.0, 1.0, 3)
        alpha = rng.normal(0.0, 4.0) * np.asarray(axes, float) if not all(axes) else rng.normal(0.0, 4.0, 3)
        a_W = rng.normal(0.0, 2.0, 3) if tilt else np.zeros(3)
        if not rotate:
            w = alpha = np.zeros(3)
        samples.append(np.concatenate([w, alpha, R_WK.T @ (a_W - G_W)]))
    return np.array(samples)


def identify(kinematics, wrenches, criteria=None) -> pd.DynamicPayloadSolution:
    identifier = pd.DynamicPayloadIdentifier(criteria=criteria)
    for k, w in zip(kinematics, wrenches, strict=True):
        identifier.add(w, k)
    return identifier.solve()


def readings(kinematics, rng=None, phi=PHI, bias=BIAS):
    wrenches = np.array([pd.predicted_wrench(phi, bias, k) for k in kinematics])
    return wrenches if rng is None else wrenches + rng.normal(0.0, 1.0, wrenches.shape) * NOISE


@pytest.mark.parametrize("seed", range(5))
def test_the_regressor_is_drakes_inverse_dynamics(seed):
    """The wrench the sensor applies on a free body (Drake's inverse dynamics of its floating joint,
    gravity included, at a random state and acceleration) is ``Y(w, alpha, a - g) phi`` in K: the
    sign convention and every term of the Newton-Euler regressor."""
    rng = np.random.default_rng(seed)
    m, p, I_cm = random_inertia(rng)
    plant = MultibodyPlant(0.0)
    body = plant.AddRigidBody("payload", SpatialInertia.MakeFromCentralInertia(
        m, p, RotationalInertia(*pd.moments_products(I_cm))))
    plant.Finalize()
    context = plant.CreateDefaultContext()
    X_WK = RigidTransform(RotationMatrix(Rotation.random(random_state=rng).as_matrix()), rng.normal(0, 1, 3))
    plant.SetFreeBodyPose(context, body, X_WK)
    v, vdot = rng.normal(0.0, 2.0, 6), rng.normal(0.0, 10.0, 6)  # [w_WK_W; v_WKo_W] and its derivative
    plant.SetVelocities(context, v)
    forces = MultibodyForces_[float](plant)
    plant.CalcForceElementsContribution(context, forces)  # gravity
    F_W = plant.CalcInverseDynamics(context, vdot, forces)  # [tau; f] on the body at Ko, in W
    R_WK = X_WK.rotation().matrix()
    kinematics = pd.sensor_kinematics(R_WK, v[:3], vdot[:3], vdot[3:], plant.gravity_field().gravity_vector())
    wrench_K = pd.regressor(kinematics) @ pd.inertial_parameters(m, p, I_cm)
    expected = np.concatenate([R_WK.T @ F_W[:3], R_WK.T @ F_W[3:]])
    assert np.abs(wrench_K - expected).max() < 1e-10 * max(1.0, np.abs(expected).max())


def test_at_rest_it_is_the_static_convention():
    """At rest ``R_WK f_K = -m g_W`` and ``tau_K = p_KCm x f_K`` (``payload``'s convention)."""
    R_WK = Rotation.from_euler("xyz", [0.4, 1.0, -0.3]).as_matrix()
    kinematics = pd.sensor_kinematics(R_WK, np.zeros(3), np.zeros(3), np.zeros(3), G_W)
    tau, f = np.split(pd.regressor(kinematics) @ PHI, 2)
    assert np.allclose(R_WK @ f, -MASS * G_W, atol=1e-12)
    assert np.allclose(tau, np.cross(P_KCM, f), atol=1e-12)


def test_inertial_parameters_round_trip():
    m, p, I_cm = pd.central_inertia(PHI)
    assert m == pytest.approx(MASS) and np.allclose(p, P_KCM, atol=1e-15)
    assert np.allclose(I_cm, I_CM, atol=1e-15)
    assert pd.physical_inertia_problem(I_cm) is None
    assert "positive definite" in pd.physical_inertia_problem(np.diag([0.0, 1.0, 1.0]))
    assert "triangle" in pd.physical_inertia_problem(np.diag([1.0, 1.0, 3.0]))


@pytest.mark.parametrize("seed", range(3))
def test_a_noise_free_stream_recovers_the_parameters_and_the_bias_exactly(seed):
    rng = np.random.default_rng(seed)
    m, p, I_cm = random_inertia(rng)
    phi, bias = pd.inertial_parameters(m, p, I_cm), rng.normal(0.0, 0.5, 6)
    kinematics = rich_stream(100, rng)
    solution = identify(kinematics, readings(kinematics, phi=phi, bias=bias))
    assert solution.verdict.converged, solution.verdict
    assert np.abs(solution.phi - phi).max() < 1e-9 * np.abs(phi).max()
    assert np.abs(solution.bias - bias).max() < 1e-9
    assert np.abs(solution.I_Cm_K - I_cm).max() < 1e-8 * np.abs(I_cm).max()


def test_sensor_noise_gives_errors_within_the_covariance():
    rng = np.random.default_rng(7)
    kinematics = rich_stream(400, rng)
    identifier = pd.DynamicPayloadIdentifier()
    for k, w in zip(kinematics, readings(kinematics, rng), strict=True):
        identifier.add(w, k)
    solution = identifier.solve()
    assert solution.verdict.converged, solution.verdict
    covariance = dynamic_payload_covariance(identifier.core.S, identifier.core.weight, solution.x)
    sd = np.sqrt(np.diagonal(covariance))
    assert np.all(np.abs(solution.x[:16] - np.concatenate([PHI, BIAS])) < 5.0 * sd)
    sd_mass, sd_com, sd_inertia = dynamic_payload_errors(covariance, solution.phi)
    assert sd_mass < 1e-3 * MASS and sd_com < 2e-4 and sd_inertia < 0.05 * 0.0058  # a rich stream
    assert abs(solution.mass - MASS) < 5 * sd_mass and np.linalg.norm(solution.p_KCm - P_KCM) < 5 * sd_com
    assert np.linalg.norm(solution.I_Cm_K - I_CM) < 5 * sd_inertia


DEGENERATE = {
    "no rotation": (dict(rotate=False), observability.NO_ROTATION),
    "one axis": (dict(axes=(0, 0, 1)), observability.ONE_AXIS),
    "one orientation": (dict(tilt=False), observability.ONE_ORIENTATION),
    "one orientation, no rotation": (dict(tilt=False, rotate=False), observability.ONE_ORIENTATION),
}


@pytest.mark.parametrize("noise", [False, True], ids=["noise-free", "noisy"])
@pytest.mark.parametrize("case", DEGENERATE, ids=list(DEGENERATE))
def test_degenerate_motion_is_not_converged_with_its_reason(case, noise):
    rng = np.random.default_rng(3)
    kwargs, reason = DEGENERATE[case]
    kinematics = rich_stream(300, rng, **kwargs)
    solution = identify(kinematics, readings(kinematics, rng if noise else None))
    assert not solution.verdict.converged
    assert solution.verdict.reason.startswith(reason), solution.verdict.reason
    assert np.isfinite(solution.x).all() and np.isfinite(solution.phi).all()


def test_a_weak_rotation_is_weakly_determined():
    """Slow turns under noise: rich in directions but not in angular acceleration."""
    rng = np.random.default_rng(4)
    kinematics = rich_stream(200, rng)
    kinematics[:, :6] *= 0.02  # 0.08 rad/s^2 RMS
    solution = identify(kinematics, readings(kinematics, rng))
    assert not solution.verdict.converged
    assert solution.verdict.reason.startswith(observability.WEAKLY_DETERMINED), solution.verdict.reason
    assert "turn the payload faster" in solution.verdict.reason


def test_a_negated_wrench_is_not_converged():
    rng = np.random.default_rng(5)
    kinematics = rich_stream(100, rng)
    solution = identify(kinematics, -readings(kinematics))
    assert not solution.verdict.converged and "not positive" in solution.verdict.reason


def test_streaming_state_round_trips_and_forgets():
    rng = np.random.default_rng(6)
    kinematics = rich_stream(60, rng)
    wrenches = readings(kinematics, rng)
    a = pd.DynamicPayloadIdentifier()
    for k, w in zip(kinematics, wrenches, strict=True):
        a.add(w, k)
    b = pd.DynamicPayloadIdentifier()
    b.set_state(a.state)
    assert np.array_equal(a.solve().x, b.solve().x)
    assert a.sample_error(wrenches[0], kinematics[0], a.solve().x) < 1e-2
    b.reset()
    assert b.solve().verdict.reason == "no samples"


@pytest.mark.parametrize(("call", "words"), [
    (lambda i: i.add(np.zeros(5), np.zeros(9)), "wrench_K must be a 6-vector"),
    (lambda i: i.add(np.zeros(6), [0.0] * 8), "kinematics_K must be a 9-vector"),
    (lambda i: i.add(np.full(6, np.nan), np.zeros(9)), "wrench_K must be finite"),
    (lambda i: i.add(np.zeros(6), np.full(9, np.inf)), "kinematics_K must be finite"),
    (lambda i: i.add(np.full(6, 1e70), np.zeros(9)), "too large"),
    (lambda i: pd.DynamicPayloadIdentifier(torque_length=0.0), "torque_length must be a positive"),
    (lambda i: pd.central_inertia(np.zeros(10)), "mass must be positive"),
])  # fmt: skip
def test_bad_input_is_a_one_line_error(call, words):
    identifier = pd.DynamicPayloadIdentifier()
    with pytest.raises(IdentificationError) as error:
        call(identifier)
    assert words in str(error.value) and "\n" not in str(error.value)
    assert identifier.num_samples == 0


def test_rls_converges_on_a_rich_stream():
    rng = np.random.default_rng(8)
    kinematics = rich_stream(400, rng)
    rls = DynamicPayloadRLS(forgetting_factor=0.999)
    identified_at = None
    for i, (k, w) in enumerate(zip(kinematics, readings(kinematics, rng), strict=True)):
        rls.add(w, k)
        if identified_at is None and rls.identified():
            identified_at = i
    assert identified_at is not None and identified_at < 100
    m, p, I_cm = pd.central_inertia(rls.phi)
    assert abs(m - MASS) < 1e-3 * MASS and np.linalg.norm(p - P_KCM) < 5e-4
    assert np.linalg.norm(I_cm - I_CM, 2) < 0.05 * 0.0058 and np.abs(rls.bias - BIAS).max() < 0.01


def test_rls_is_least_squares_without_forgetting():
    rng = np.random.default_rng(9)
    Y, theta = rng.normal(size=(60, 4)), np.array([1.0, -2.0, 0.5, 3.0])
    y = Y @ theta + rng.normal(0.0, 0.01, 60)
    rls = RecursiveLeastSquares(4, 1.0, initial_variance=1e8)
    for rows in range(0, 60, 3):
        rls.add(Y[rows : rows + 3], y[rows : rows + 3])
    assert np.allclose(rls.theta, np.linalg.lstsq(Y, y, rcond=None)[0], atol=1e-8)
    assert rls.residual_variance == pytest.approx(np.sum((y - Y @ rls.theta) ** 2) / 56, rel=1e-3)


def test_rls_does_not_identify_without_rotation():
    rng = np.random.default_rng(10)
    kinematics = rich_stream(300, rng, rotate=False)
    rls = DynamicPayloadRLS()
    for k, w in zip(kinematics, readings(kinematics, rng), strict=True):
        rls.add(w, k)
    assert not rls.identified()


def test_the_encoder_filter_is_exact_on_cubics_at_any_instant_of_its_window():
    period, t = 0.01, (np.arange(11) - 5) * 0.01
    c = np.array([0.3, -1.2, 2.5, 4.0])  # q(t) = c0 + c1 t + c2 t^2 + c3 t^3
    polyval = np.polynomial.polynomial.polyval
    q = polyval(t, c)
    for at in (0.0, -0.002, 0.03):
        expected = [polyval(at, c), polyval(at, [c[1], 2 * c[2], 3 * c[3]]),
                    polyval(at, [2 * c[2], 6 * c[3]])]  # fmt: skip
        assert np.allclose(savitzky_golay_weights(11, 3, period, at) @ q, expected, atol=1e-9)
    assert np.allclose(joint_derivatives(np.column_stack([q, 2 * q]), period)[:, 1], 2 * np.array(
        [c[0], c[1], 2 * c[2]]), atol=1e-9)  # fmt: skip


def test_the_encoder_filters_noise_gains_are_its_weights_norms():
    rng = np.random.default_rng(11)
    W = savitzky_golay_weights(11, 3, 0.01)
    noise = rng.normal(0.0, 1e-4, (20000, 11)) @ W.T
    assert np.allclose(noise.std(axis=0), 1e-4 * noise_gains(11, 3, 0.01), rtol=0.03)


@pytest.mark.parametrize(("args", "words"), [
    ((10, 3, 0.01), "odd"), ((11, 1, 0.01), "order must be an integer >= 2"), ((5, 5, 0.01), "<= 4"),
    ((11, 3, 0.0), "period must be a positive"), ((11, 3, 0.01, 0.06), "within the window"),
])  # fmt: skip
def test_the_encoder_filter_refuses_bad_settings(args, words):
    with pytest.raises(IdentificationError, match=words):
        savitzky_golay_weights(*args)


def test_criteria_are_the_static_modes():
    criteria = ConvergenceCriteria(max_expected_rms=0.3, min_gap_ratio=3000.0, max_ssd=None)
    assert pd.DynamicPayloadIdentifier(criteria=criteria).criteria is criteria


@pytest.mark.parametrize("dimensions, radius", [(1, 1.960), (3, 1.614), (6, 1.449)])
def test_a_95_percent_region_holds_95_percent_of_normal_errors(dimensions, radius):
    errors = np.random.default_rng(dimensions).normal(size=(200_000, dimensions))
    rms = math.sqrt(dimensions)  # sqrt(trace) of the identity
    assert observability.region_95(dimensions) == pytest.approx(radius, abs=1e-3)
    inside = np.linalg.norm(errors, axis=1) <= observability.region_95(dimensions) * rms
    assert inside.mean() == pytest.approx(0.95, abs=0.003)


@pytest.mark.parametrize("shape", ["isotropic", "one direction", "two of six", "random"])
def test_the_95_percent_radius_holds_95_percent_whatever_the_covariances_shape(shape):
    rng = np.random.default_rng(7)
    k = 3 if shape == "isotropic" else 6
    L = {"isotropic": np.eye(3), "one direction": np.diag([1.0, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3]),
         "two of six": np.diag([1.0, 0.7, 0.05, 0.05, 0.05, 0.05]), "random": rng.normal(size=(6, 6))}[shape]
    covariance = L @ L.T
    errors = rng.normal(size=(200_000, k)) @ L.T
    radius = observability.radius_95(covariance)
    assert np.mean(np.linalg.norm(errors, axis=1) <= radius) == pytest.approx(0.95, abs=0.006)
    if shape == "isotropic":
        assert radius == pytest.approx(observability.region_95(3) * math.sqrt(3.0), rel=1e-3)
    if shape == "one direction":
        assert radius == pytest.approx(1.96, rel=0.01)
    assert observability.radius_95(np.zeros((3, 3))) == 0.0


def _first_declared(kinematics, wrenches):
    """The first converged solution of the stream fed sample by sample (None if none)."""
    identifier = pd.DynamicPayloadIdentifier()
    for k, w in zip(kinematics, wrenches, strict=True):
        identifier.add(w, k)
        if identifier.num_samples >= 30 and identifier.solve().verdict.converged:
            return identifier.solve()
    return None


def test_a_declared_payload_lies_within_the_accuracy_it_is_declared_at():
    """Slow turns (0.4 rad/s^2 RMS) under an ATI Mini40's noise: the verdict waits until the 95 %
    regions lie within the accuracy, so the estimate it declares first is within it on ~95 % of the
    streams (the inertia binds; under 1 sd bounds it declared with errors up to twice them)."""
    rng = np.random.default_rng(12)
    declared, within, at = 0, 0, []
    for _ in range(40):
        kinematics = rich_stream(600, rng)
        kinematics[:, :6] *= 0.1
        solution = _first_declared(kinematics, readings(kinematics, rng))
        if solution is None:
            continue
        declared += 1
        at.append(solution.num_samples)
        m, p, I_cm = pd.central_inertia(solution.phi)
        within += (abs(m - MASS) <= dyn_obs.MASS_ACCURACY * MASS
                   and np.linalg.norm(p - P_KCM) <= dyn_obs.COM_ACCURACY
                   and np.linalg.norm(I_cm - I_CM, 2) <= dyn_obs.INERTIA_ACCURACY * 0.0058
                   and np.abs(solution.bias[:3] - BIAS[:3]).max() <= dyn_obs.BIAS_TORQUE_ACCURACY
                   and np.abs(solution.bias[3:] - BIAS[3:]).max() <= dyn_obs.BIAS_FORCE_ACCURACY)
    assert declared == 40 and min(at) > 40  # the regions, not the 30-sample floor, decide
    assert within >= 37, f"{within} of {declared} within the accuracy"


def test_each_bound_of_the_accuracy_holds_a_declaration_back():
    x = np.concatenate([PHI, BIAS])
    base = np.diag(np.full(16, 1e-14))
    assert dyn_obs.accuracy_problem(base, x) is None
    # the sd of the mass, of h_x (kg m: the centre of mass times m), of b_tau_x and of b_f_x
    bounds = ((0, dyn_obs.MASS_ACCURACY * MASS, "mass"), (1, dyn_obs.COM_ACCURACY * MASS, "centre of mass"),
              (10, dyn_obs.BIAS_TORQUE_ACCURACY, "torque bias"), (13, dyn_obs.BIAS_FORCE_ACCURACY, "force"))
    for index, bound, words in bounds:
        covariance = base.copy()
        covariance[index, index] = (1.1 * bound / observability.region_95(1)) ** 2  # one direction
        regions = dyn_obs.payload_regions_95(covariance, x)
        assert max(regions.values()) > 1.0, words
        problem = dyn_obs.accuracy_problem(covariance, x)
        assert problem.startswith(observability.WEAKLY_DETERMINED) and "95 % region" in problem
        covariance[index, index] /= 1.21 * 1.05  # just within the bound
        assert dyn_obs.accuracy_problem(covariance, x) is None, words


def test_the_dynamic_mode_takes_its_own_gap_and_the_static_mode_the_scenarios():
    coordination = CoordinationConfig(max_expected_rms=0.3, min_gap_ratio=3000.0, noise_rms=0.05)
    dynamic = payload_formulation(KinestheticConfig(mode="dynamic", coordination=coordination))
    static = payload_formulation(KinestheticConfig(mode="static", coordination=coordination))
    assert dynamic.criteria.min_gap_ratio == pd.MIN_GAP_RATIO and static.criteria.min_gap_ratio == 3000.0
    assert dynamic.criteria.max_expected_rms == static.criteria.max_expected_rms == 0.3
