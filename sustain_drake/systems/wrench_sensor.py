"""The wrist force/torque sensor: a weld's reaction force read as a noisy, biased sensor."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.tree import JointIndex
from pydrake.systems.framework import LeafSystem


class WristWrenchSensor(LeafSystem):
    """Reads the reaction force of the sensor weld and outputs it as the sensor's reading.

    .. pydrake_system::

        name: WristWrenchSensor
        input_ports:
        - reaction_forces
        - X_WK (only with gripper compensation)
        output_ports:
        - wrench

    ``reaction_forces`` is ``MultibodyPlant.get_reaction_forces_output_port()`` (one
    ``SpatialForce`` per joint, indexed by ``JointIndex``). ``wrench`` is the 6-vector
    ``[tau_x, tau_y, tau_z, f_x, f_y, f_z]`` (N m, N; Drake's SpatialForce order, torque
    first).

    Sign convention (the identification math relies on it): the sensor frame K is the weld's
    frame Jc on the child (gripper) side, and the reading is the spatial force APPLIED BY THE
    PARENT (wrist) ON THE CHILD SIDE (gripper + held tool), about K's origin, expressed in K.
    That is the plant's ``F_CJc_Jc`` for the weld. At rest, with an outboard mass m whose
    centre of mass is at ``p_KCm`` and gravity ``g_W``: ``R_WK f_K = -m g_W`` (points up) and
    ``tau_K = p_KCm x f_K``.

    The reading is sampled at ``period`` (a zero-order hold kept in discrete state, so
    contexts can be cloned) with Gaussian noise of standard deviations ``force_noise`` (N)
    and ``torque_noise`` (N m) per axis, plus a constant ``bias``. The noise of the k-th
    sample is drawn from a generator seeded with ``(seed, k)``: a simulation is reproducible
    and independent of how it is advanced.

    With ``compensation = GripperCompensation(mass, p_KCg)``, the sensor subtracts the static
    wrench of the gripper's own weight (mass in kg, centre of mass ``p_KCg`` in K), as F/T
    sensor software does after a tool calibration; it then reads the pose ``X_WK``
    (``RigidTransform``) to know where gravity points, and the reading at rest is the held
    object's weight alone.
    """

    def __init__(self, joint_index: JointIndex | int, period: float,
                 force_noise: float = 0.0, torque_noise: float = 0.0,
                 bias=(0.0,) * 6, seed: int = 0,
                 compensation: GripperCompensation | None = None):
        super().__init__()
        if not period > 0:
            raise ValueError(f"period must be > 0, got {period}")
        if force_noise < 0 or torque_noise < 0:
            raise ValueError("noise standard deviations must be >= 0")
        bias = np.asarray(bias, dtype=float)
        if bias.shape != (6,) or not np.all(np.isfinite(bias)):
            raise ValueError("bias must be 6 finite numbers [tau_x, tau_y, tau_z, f_x, f_y, f_z]")
        self._joint = int(joint_index)
        self._period = float(period)
        self._sigma = np.array([torque_noise] * 3 + [force_noise] * 3, dtype=float)
        self._bias = bias
        self._seed = int(seed)
        self._forces = self.DeclareAbstractInputPort(
            "reaction_forces", AbstractValue.Make([SpatialForce()]))
        self._compensation = compensation
        self._X_WK = None
        if compensation is not None:
            self._X_WK = self.DeclareAbstractInputPort(
                "X_WK", AbstractValue.Make(RigidTransform()))
        state = self.DeclareDiscreteState(6)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._sample)
        # A first reading at t = 0, so the output is never an unmeasured zero.
        self.DeclareInitializationDiscreteUpdateEvent(self._sample)
        self.DeclareStateOutputPort("wrench", state)

    def _sample(self, context, discrete_state) -> None:
        forces = self._forces.Eval(context)
        if self._joint >= len(forces):
            raise RuntimeError(f"reaction_forces has no entry for joint index {self._joint}")
        reading = wrench_vector(forces[self._joint]) + self._bias
        if self._compensation is not None:
            R_KW = self._X_WK.Eval(context).rotation().inverse()
            reading = reading - self._compensation.static_wrench(R_KW)
        if np.any(self._sigma > 0):
            k = int(round(context.get_time() / self._period))
            rng = np.random.default_rng([self._seed, k])
            reading = reading + self._sigma * rng.standard_normal(6)
        discrete_state.set_value(0, reading)


@dataclass(frozen=True)
class GripperCompensation:
    """The gripper's own mass (kg) and centre of mass ``p_KCg`` (m, in K), and gravity."""

    mass: float
    p_KCg: tuple[float, float, float]
    g_W: tuple[float, float, float] = (0.0, 0.0, -9.81)

    def static_wrench(self, R_KW) -> np.ndarray:
        """``[tau_K, f_K]`` the wrist applies to hold the gripper still at orientation R_KW."""
        f_K = -self.mass * (R_KW @ np.asarray(self.g_W, dtype=float))
        return np.concatenate([np.cross(np.asarray(self.p_KCg, dtype=float), f_K), f_K])


def wrench_vector(F) -> np.ndarray:
    """A ``SpatialForce`` as ``[tau, f]``, the order of the ``wrench`` port."""
    return np.concatenate([F.rotational(), F.translational()])


