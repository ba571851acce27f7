"""Arm postures for touching the table with the held tool (inverse kinematics at build time)."""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RigidBody
from scipy.optimize import least_squares

from sustain_drake.station.scenario import ScenarioError, TouchMotionConfig, TouchTarget
from sustain_drake.systems.touch_motion import TouchPosture

# A posture is accepted when the point is within 0.5 mm and the direction within ~0.1 deg.
_TOLERANCE = 5e-4
_SEEDS = 12


class _Kinematics:
    """Forward kinematics of the tool body over the arm's joints (other joints at default)."""

    def __init__(self, plant: MultibodyPlant, tool_body: RigidBody, joints):
        self.plant = plant
        self.context = plant.CreateDefaultContext()
        self.tool = tool_body
        self.joints = list(joints)
        self.lower = np.array([j.position_lower_limits()[0] for j in self.joints])
        self.upper = np.array([j.position_upper_limits()[0] for j in self.joints])

    def X_WT(self, q):
        for joint, angle in zip(self.joints, q, strict=True):
            joint.set_angle(self.context, float(angle))
        return self.plant.EvalBodyPoseInWorld(self.context, self.tool)


def solve_touch_posture(kin: _Kinematics, target: TouchTarget, p_WQ: np.ndarray, q_hint: np.ndarray,
                        seed: int, near_hint: bool = True) -> np.ndarray | None:  # fmt: skip
    """Joint angles putting the tool's point ``target.p_TQ`` at ``p_WQ`` with ``down_T`` along
    world -z (3 + 2 equations, one unknown per arm joint) from several least-squares starts: the
    solution nearest ``q_hint`` (``near_hint``) or the one farthest from the joint limits; None
    when no start reaches it within the joint limits."""
    p_TQ = np.asarray(target.p_TQ, dtype=float)
    d_T = np.asarray(target.down_T, dtype=float) / np.linalg.norm(target.down_T)
    down_W = np.array([0.0, 0.0, -1.0])

    def residual(q):
        X = kin.X_WT(q)
        # 0.1 m per radian of direction error: both terms in metres.
        return np.concatenate([X.multiply(p_TQ) - p_WQ, 0.1 * (X.rotation().matrix() @ d_T - down_W)])

    rng = np.random.default_rng(seed)
    best, best_cost = None, np.inf
    starts = [np.clip(q_hint, kin.lower, kin.upper)]
    starts += [rng.uniform(0.9 * kin.lower, 0.9 * kin.upper) for _ in range(_SEEDS)]
    for q0 in starts:
        sol = least_squares(residual, q0, bounds=(kin.lower, kin.upper), xtol=1e-12, ftol=1e-12)
        if np.max(np.abs(sol.fun)) < _TOLERANCE:
            if near_hint:
                cost = float(np.sum((sol.x - q_hint) ** 2))
            else:
                cost = -float(np.min(np.minimum(sol.x - kin.lower, kin.upper - sol.x)))
            if cost < best_cost:
                best, best_cost = sol.x, cost
            if near_hint and q0 is starts[0]:
                break  # the hint's own neighbourhood: keep it (continuity of the path)
    return best


def touch_postures(plant: MultibodyPlant, tool_body: RigidBody, config: TouchMotionConfig,
                   table_height: float, q_initial, joints) -> list[TouchPosture]:  # fmt: skip
    """``q_above`` / ``q_press`` for each target over the arm's ``joints`` (base to hand); an
    unreachable target is a ``ScenarioError``."""
    kin = _Kinematics(plant, tool_body, joints)
    postures = []
    q_hint = np.asarray(q_initial, dtype=float)
    for i, target in enumerate(config.targets):
        x, y = target.p_WQ
        # At the table top first (from several starts), then above and below it from there, so
        # the descent is a short, nearly straight joint-space path.
        surface = solve_touch_posture(kin, target, np.array([x, y, table_height]), q_hint, seed=i,
                                      near_hint=False)
        above = press = high = None
        if surface is not None:
            high = solve_touch_posture(kin, target, np.array([x, y, table_height + config.retreat_height]),
                                       surface, seed=300 + i)  # fmt: skip
            above = solve_touch_posture(kin, target, np.array([x, y, table_height + config.approach_height]),
                                        surface, seed=100 + i)  # fmt: skip
            press = solve_touch_posture(kin, target, np.array([x, y, table_height - config.press_depth]),
                                        surface, seed=200 + i)  # fmt: skip
        if above is None or press is None or high is None:
            raise ScenarioError(f"touch_motion.targets[{i}]: the arm cannot reach it (joint limits)")
        postures.append(TouchPosture(tuple(above), tuple(press), tuple(high)))
        q_hint = above
    return postures
