"""Touch estimation on the held object (§3.5): the line of action meets the known shape."""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from scipy.spatial.transform import Rotation

from sustain_drake.identification import payload_dynamic
from sustain_drake.identification.payload import STANDARD_GRAVITY_W
from sustain_drake.identification.touch import Box, Cylinder, Sphere, locate_touch, predicted_wrench


def pose(rpy=(0.0, 0.0, 0.0), p=(0.0, 0.0, 0.0)):
    X = np.eye(4)
    X[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    X[:3, 3] = p
    return X


def residual_for(p_KP, F_env_K):
    """The sensor's extra wrench [tau_c; f_c] balancing F_env applied at P (f_c = -F_env)."""
    f_c = -np.asarray(F_env_K, dtype=float)
    return np.concatenate([np.cross(p_KP, f_c), f_c])


X_KG = pose((0.2, -0.1, 0.4), (0.01, -0.02, 0.15))


@pytest.mark.parametrize(
    ("shape", "p_GP", "n_G"),
    [
        (Box((0.1, 0.08, 0.06)), [0.02, -0.01, 0.03], [0, 0, 1]),  # top face
        (Sphere(0.05), 0.05 * np.array([0.6, 0.0, 0.8]), [0.6, 0.0, 0.8]),
        (Cylinder(0.03, 0.2), [0.03, 0.0, 0.05], [1, 0, 0]),  # side
        (Cylinder(0.03, 0.2), [0.01, -0.01, -0.1], [0, 0, -1]),  # bottom cap
    ],
)
def test_known_contact_is_recovered(shape, p_GP, n_G):
    p_KP = X_KG[:3, :3] @ np.asarray(p_GP, float) + X_KG[:3, 3]
    n_K = X_KG[:3, :3] @ np.asarray(n_G, float)
    # The environment pushes into the surface, with a tangential (friction) part.
    tangent = np.cross(n_K, [0.3, -0.5, 0.8])
    F_env = -6.0 * n_K / np.linalg.norm(n_K) + 1.5 * tangent / np.linalg.norm(tangent)
    touch = locate_touch(residual_for(p_KP, F_env), shape, X_KG)
    assert touch.distance == 0.0
    assert np.linalg.norm(touch.p_KP - p_KP) < 1e-9
    assert np.allclose(touch.f_env_K, F_env)
    assert float(touch.n_K @ F_env) < 0  # pushing into the surface


def test_a_corner_pushed_towards_the_centre():
    p_GP = np.array([-0.05, 0.04, -0.03])  # a corner of the box
    p_KP = X_KG[:3, :3] @ p_GP + X_KG[:3, 3]
    F_env = X_KG[:3, :3] @ (-8.0 * p_GP / np.linalg.norm(p_GP))
    touch = locate_touch(residual_for(p_KP, F_env), Box((0.1, 0.08, 0.06)), X_KG)
    assert touch.distance == 0.0 and np.linalg.norm(touch.p_KP - p_KP) < 1e-9


def test_the_kept_intersection_is_where_the_force_pushes_in():
    box = Box((0.2, 0.2, 0.2))
    # Pushing down on the top face at (0, 0, 0.1): the line also crosses the bottom face.
    touch = locate_touch(residual_for([0.0, 0.0, 0.1], [0.0, 0.0, -5.0]), box, np.eye(4))
    assert np.allclose(touch.p_KP, [0.0, 0.0, 0.1])
    # The same line with the force reversed (pulling up = pushing up on the bottom face).
    touch = locate_touch(residual_for([0.0, 0.0, -0.1], [0.0, 0.0, 5.0]), box, np.eye(4))
    assert np.allclose(touch.p_KP, [0.0, 0.0, -0.1])


def test_no_force_no_touch_and_a_miss_is_flagged():
    assert locate_touch(np.zeros(6), Sphere(0.1), np.eye(4)) is None
    touch = locate_touch(residual_for([0.5, 0.0, 0.0], [0.0, 0.0, -5.0]), Sphere(0.1), np.eye(4))
    assert touch.distance == pytest.approx(0.4)


def test_predicted_wrench_matches_the_payload_convention():
    R = Rotation.from_euler("xyz", [0.3, 1.0, -0.2]).as_matrix()
    w = predicted_wrench(0.6, np.array([0.0, 0.01, 0.1]), R, STANDARD_GRAVITY_W)
    assert (R @ w[3:])[2] == pytest.approx(0.6 * 9.81)
    assert np.allclose(w[:3], np.cross([0.0, 0.01, 0.1], w[3:]))


def test_touch_estimator_system_on_a_synthetic_wrench():
    from pydrake.geometry import Box as DrakeBox
    from pydrake.math import RigidTransform, RollPitchYaw
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

    from sustain_drake.identification.payload import PayloadIdentifier
    from sustain_drake.systems.touch_estimator import TouchEstimator

    mass, p_KCm = 0.6, np.array([0.0, 0.0, 0.12])
    # A payload solution identified from exact data.
    ident = PayloadIdentifier()
    for R in Rotation.random(20, random_state=1).as_matrix():
        ident.add(predicted_wrench(mass, p_KCm, R, STANDARD_GRAVITY_W), R)
    solution = ident.solve()
    assert solution.verdict.converged
    X_WK = RigidTransform(RollPitchYaw(0.3, -0.4, 1.0), [0.4, 0.1, 0.5])
    R_WK = X_WK.rotation().matrix()
    X_KG = RigidTransform([0.0, 0.0, 0.12])
    p_KP = np.array([0.03, -0.02, 0.12 + 0.05])  # on the box's +z face (box 0.1 x 0.08 x 0.1)
    F_env_K = R_WK.T @ np.array([0.5, 0.0, 6.0])
    F_env_K = F_env_K if F_env_K[2] < 0 else -F_env_K  # pushing into the +z face
    reading = predicted_wrench(mass, p_KCm, R_WK, STANDARD_GRAVITY_W) + residual_for(p_KP, F_env_K)

    def run(wrench, kinematics=None):
        builder = DiagramBuilder()
        est = builder.AddSystem(TouchEstimator(DrakeBox(0.1, 0.08, 0.1), X_KG, min_force=2.0))
        sources = [
            ("wrench", ConstantVectorSource(wrench)),
            ("X_WK", ConstantValueSource(AbstractValue.Make(X_WK))),
            ("payload", ConstantValueSource(AbstractValue.Make(solution))),
            ("allowable_error", ConstantVectorSource([100 * max(solution.expected_mse, 1e-8)])),
        ]
        if kinematics is not None:
            sources.append(("kinematics_K", ConstantVectorSource(kinematics)))
        for port, source in sources:
            builder.Connect(builder.AddSystem(source).get_output_port(), est.GetInputPort(port))
        diagram = builder.Build()
        ctx = est.GetMyContextFromRoot(diagram.CreateDefaultContext())
        return {n: est.GetOutputPort(n).Eval(ctx) for n in ("touch", "p_KP", "p_WP", "f_env_W")}

    out = run(reading)
    assert out["touch"][0] == 1.0
    assert np.linalg.norm(out["p_KP"] - p_KP) < 1e-6
    assert np.linalg.norm(out["p_WP"] - X_WK.multiply(p_KP)) < 1e-6
    assert np.allclose(out["f_env_W"], R_WK @ F_env_K)
    # Free motion: the reading is the payload's own wrench (plus sensor noise): no touch.
    rng = np.random.default_rng(0)
    noise = np.concatenate([rng.normal(0, 5e-4, 3), rng.normal(0, 0.02, 3)])
    quiet = run(predicted_wrench(mass, p_KCm, R_WK, STANDARD_GRAVITY_W) + noise)
    assert quiet["touch"][0] == 0.0 and not quiet["p_KP"].any()

    # A fast move (5 m/s^2 of the sensor, turning at 2 rad/s and 4 rad/s^2): the payload's inertial
    # force is 3 N, a false touch under the quasi-static prediction; with the sensor's kinematics the
    # moving payload's wrench is predicted and it is not a touch, while a touch during the move
    # still is, at the same point.
    g_K = R_WK.T @ STANDARD_GRAVITY_W
    kinematics = np.concatenate([[0.0, 2.0, 0.5], [4.0, 0.0, -1.0], np.array([5.0, 0.0, 0.0]) - g_K])
    phi = payload_dynamic.inertial_parameters(mass, p_KCm, np.zeros((3, 3)))
    moving = payload_dynamic.predicted_wrench(phi, np.zeros(6), kinematics)
    assert np.linalg.norm(moving[3:] - predicted_wrench(mass, p_KCm, R_WK, STANDARD_GRAVITY_W)[3:]) > 3.0
    assert run(moving + noise)["touch"][0] == 1.0  # quasi-static: taken for a touch
    assert run(moving + noise, kinematics)["touch"][0] == 0.0
    touched = run(moving + residual_for(p_KP, F_env_K), kinematics)
    assert touched["touch"][0] == 1.0 and np.linalg.norm(touched["p_KP"] - p_KP) < 1e-6
