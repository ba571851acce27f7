"""Poses and ground truth from the plant's body poses (hand pose; evaluation-only truth)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem

from sustain_drake.identification.payload_dynamic import N_INERTIAL, inertia_matrix, inertial_parameters


@dataclass(frozen=True)
class PointMass:
    """A body's mass (kg), centre of mass ``p_BCm`` (m, in the body frame B) and rotational inertia
    about it ``I_BBcm`` (kg m^2, in B: ``[I_xx, I_yy, I_zz, I_xy, I_xz, I_yz]``; zeros: a point mass)."""

    body_index: int
    mass: float
    p_BCm: tuple[float, float, float]
    I_BBcm: tuple[float, float, float, float, float, float] = (0.0,) * 6


class GroundTruth(LeafSystem):
    """Computes the hand pose and the ground truth the identifiers are evaluated against.

    .. pydrake_system::

        name: GroundTruth
        input_ports:
        - body_poses
        output_ports:
        - X_WH
        - X_WL
        - true_X_WC
        - true_p_HP
        - true_X_HT
        - true_tool_mass
        - true_p_KCm
        - true_outboard_mass
        - true_p_KCo
        - true_tool_inertia
        - true_outboard_inertia

    ``body_poses`` is ``MultibodyPlant.get_body_poses_output_port()``. Outputs:

    - ``X_WH`` (``RigidTransform``): the hand H (gripper flange body) in the world; on a real
      robot this comes from forward kinematics of the joint encoders.
    - ``X_WL`` (``RigidTransform``): the hand's parent link L (``parent_body``: the body the arm's
      last joint turns the hand on; the hand itself when not given), from the same kinematics.
    - ``true_X_WC`` (``RigidTransform``): the camera's colour frame C in the world (Drake's
      camera convention: +z out of the lens, +x right, +y down).
    - ``true_p_HP`` (3, m): the tracked tool point P in H (the grasp point if no tool).
    - ``true_X_HT`` (``RigidTransform``): the held tool's body frame T (the frame of the tracked
      point's body) in H; it changes when the tool slips in the grasp (identity if no tool).
    - ``true_tool_mass`` (1, kg) and ``true_p_KCm`` (3, m): the HELD TOOL ALONE, its mass and
      centre of mass in the sensor frame K (0 and the origin when no tool is held).
    - ``true_outboard_mass`` (1, kg) and ``true_p_KCo`` (3, m): everything outboard of the
      force/torque sensor (gripper, finger, grip joints and tool), which is what the wrench
      at rest measures: ``f_K = -m_o R_KW g_W``, ``tau_K = p_KCo x f_K``.
    - ``true_tool_inertia`` and ``true_outboard_inertia`` (10 each): the inertial parameters ``phi``
      of the held tool alone and of everything outboard (``identification.payload_dynamic``: ``[m;
      m p_KCm; I_xx, I_yy, I_zz, I_xy, I_xz, I_yz]`` about K's origin, in K; kg, kg m, kg m^2), what
      the dynamic payload identification identifies (the outboard's, from the raw wrench).

    Ground-truth ports are for evaluation only; no estimator may read them.
    """

    def __init__(self, hand_body: int, X_HK: RigidTransform, camera_body: int,
                 X_BC: RigidTransform, tool_body: int | None, p_TP, tool: PointMass | None,
                 outboard: list[PointMass], parent_body: int | None = None):
        super().__init__()
        self._hand = int(hand_body)
        parent = self._hand if parent_body is None else int(parent_body)
        self._X_HK = X_HK
        self._camera = int(camera_body)
        self._X_BC = X_BC
        self._tool_body = self._hand if tool_body is None else int(tool_body)
        self._p_TP = np.asarray(p_TP, dtype=float)
        self._tool = tool
        self._outboard = list(outboard)
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()]))
        poses_only = {self._poses.ticket()}
        self.DeclareAbstractOutputPort(
            "X_WH", lambda: AbstractValue.Make(RigidTransform()),
            lambda c, o: o.set_value(self._X_W(c, self._hand)), poses_only)
        self.DeclareAbstractOutputPort(
            "X_WL", lambda: AbstractValue.Make(RigidTransform()),
            lambda c, o: o.set_value(self._X_W(c, parent)), poses_only)
        self.DeclareAbstractOutputPort(
            "true_X_WC", lambda: AbstractValue.Make(RigidTransform()),
            lambda c, o: o.set_value(self._X_W(c, self._camera) @ self._X_BC), poses_only)
        self.DeclareVectorOutputPort("true_p_HP", BasicVector(3), self._calc_p_HP, poses_only)
        self.DeclareAbstractOutputPort(
            "true_X_HT", lambda: AbstractValue.Make(RigidTransform()),
            lambda c, o: o.set_value(self._X_HT(self._poses.Eval(c))), poses_only)
        self.DeclareVectorOutputPort(
            "true_tool_mass", BasicVector(1),
            lambda c, o: o.SetFromVector([tool.mass if tool else 0.0]), poses_only)
        self.DeclareVectorOutputPort("true_p_KCm", BasicVector(3), self._calc_p_KCm, poses_only)
        self.DeclareVectorOutputPort(
            "true_outboard_mass", BasicVector(1),
            lambda c, o: o.SetFromVector([sum(b.mass for b in self._outboard)]), poses_only)
        self.DeclareVectorOutputPort("true_p_KCo", BasicVector(3), self._calc_p_KCo, poses_only)
        for name, bodies in (("true_tool_inertia", [tool] if tool else []),
                             ("true_outboard_inertia", outboard)):
            self.DeclareVectorOutputPort(
                name, BasicVector(N_INERTIAL),
                lambda c, o, bodies=bodies: o.SetFromVector(self._inertia_in_K(c, bodies)), poses_only)

    def _X_W(self, context, body: int) -> RigidTransform:
        return self._poses.Eval(context)[body]

    def _X_KW(self, poses: list) -> RigidTransform:
        return (poses[self._hand] @ self._X_HK).inverse()

    def _X_HT(self, poses: list) -> RigidTransform:
        return poses[self._hand].inverse() @ poses[self._tool_body]

    def _calc_p_HP(self, context, output) -> None:
        poses = self._poses.Eval(context)  # once: each Eval converts every body's pose to Python
        output.SetFromVector(self._X_HT(poses) @ self._p_TP)

    def _com_in_K(self, context, masses: list[PointMass]) -> np.ndarray:
        total = sum(b.mass for b in masses)
        if total <= 0:
            return np.zeros(3)
        poses = self._poses.Eval(context)
        X_KW = self._X_KW(poses)
        weighted = sum(b.mass * (X_KW @ poses[b.body_index] @ np.asarray(b.p_BCm)) for b in masses)
        return weighted / total

    def _inertia_in_K(self, context, bodies: list[PointMass]) -> np.ndarray:
        """The sum of ``bodies``' inertial parameters about K's origin, in K."""
        poses = self._poses.Eval(context)
        X_KW = self._X_KW(poses)
        total = np.zeros(N_INERTIAL)
        for b in bodies:
            X_KB = X_KW @ poses[b.body_index]
            R_KB = X_KB.rotation().matrix()
            I_Cm_K = R_KB @ inertia_matrix(b.I_BBcm) @ R_KB.T
            total += inertial_parameters(b.mass, X_KB @ np.asarray(b.p_BCm), I_Cm_K)
        return total

    def _calc_p_KCm(self, context, output) -> None:
        output.SetFromVector(self._com_in_K(context, [self._tool] if self._tool else []))

    def _calc_p_KCo(self, context, output) -> None:
        output.SetFromVector(self._com_in_K(context, self._outboard))


class PoseToVector(LeafSystem):
    """A ``RigidTransform`` input as a 16-vector (its 4x4 matrix, row-major), for loggers.

    .. pydrake_system::

        name: PoseToVector
        input_ports:
        - pose
        output_ports:
        - matrix
    """

    def __init__(self):
        super().__init__()
        self.DeclareAbstractInputPort("pose", AbstractValue.Make(RigidTransform()))
        self.DeclareVectorOutputPort(
            "matrix", BasicVector(16),
            lambda c, o: o.SetFromVector(
                self.get_input_port(0).Eval(c).GetAsMatrix4().reshape(-1)))
