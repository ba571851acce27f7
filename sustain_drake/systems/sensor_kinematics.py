"""The wrist sensor frame's kinematics for the dynamic payload identification
(``identification.payload_dynamic``): ``kinematics_K = [w_WK_K; alpha_WK_K; a_WKo_K - g_K]`` (9;
rad/s, rad/s^2, m/s^2), from the simulated plant or, on hardware, from the joint encoders."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialAcceleration, SpatialVelocity
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem, ValueProducer

from sustain_drake.identification.differentiation import savitzky_golay_weights
from sustain_drake.identification.payload_dynamic import KINEMATICS, sensor_kinematics
from sustain_drake.identification.rotation import so3_exp


class SensorKinematicsFromPlant(LeafSystem):
    """The sensor frame's true kinematics, read off a (simulated) ``MultibodyPlant``.

    .. pydrake_system::

        name: SensorKinematicsFromPlant
        input_ports:
        - body_poses
        - body_spatial_velocities
        - body_spatial_accelerations
        output_ports:
        - kinematics_K

    Inputs are the plant's ports of the same names. ``kinematics_K`` (9) is ``[w_WK_K; alpha_WK_K;
    a_WKo_K - g_K]`` of ``sensor_frame`` (K; its body's spatial acceleration shifted to K's origin),
    with the plant's gravity, sampled every ``period`` s into the discrete state (a zero-order
    hold at the instants ``WristWrenchSensor`` samples, with a first sample at initialization): each
    wrench sample has the kinematics of its own instant.

    In a discrete plant (time step ``h``) the sampled reaction forces and accelerations are those of
    the last step, computed at the configuration and velocities it started from, while the poses and
    velocities are the state it ended in. So the kinematics are reported at the step's start: the
    orientation turned back by the step, ``R_WK exp(-h [w_WK_K x])``, and ``w - h alpha``. (Read at
    the step's end, the gravity direction is one step late: at 1.7 rad/s and ``h`` = 2 ms that is a
    3 mN m error in the box's torque, six times the sensor's noise, and errors of tens of per cent in
    the identified inertia.) A continuous plant needs no such correction.
    """

    def __init__(self, plant, sensor_frame, period: float):
        super().__init__()
        if not period > 0:
            raise ValueError(f"period must be > 0, got {period}")
        self._body = int(sensor_frame.body().index())
        self._X_BK = sensor_frame.GetFixedPoseInBodyFrame()
        self._g_W = np.array(plant.gravity_field().gravity_vector())
        self._h = float(plant.time_step())
        self._poses = self.DeclareAbstractInputPort("body_poses", AbstractValue.Make([RigidTransform()]))
        self._velocities = self.DeclareAbstractInputPort(
            "body_spatial_velocities", AbstractValue.Make([SpatialVelocity()]))
        self._accelerations = self.DeclareAbstractInputPort(
            "body_spatial_accelerations", AbstractValue.Make([SpatialAcceleration()]))
        state = self.DeclareDiscreteState(KINEMATICS)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._sample)
        self.DeclareInitializationDiscreteUpdateEvent(self._sample)
        self.DeclareStateOutputPort("kinematics_K", state)

    def _sample(self, context, discrete_state) -> None:
        X_WB = self._poses.Eval(context)[self._body]
        V_WB = self._velocities.Eval(context)[self._body]
        A_WB = self._accelerations.Eval(context)[self._body]
        w_WB = V_WB.rotational()
        A_WK = A_WB.Shift(X_WB.rotation() @ self._X_BK.translation(), w_WB)
        R_WK = (X_WB.rotation() @ self._X_BK.rotation()).matrix()
        alpha_W = A_WK.rotational()
        # Back to the configuration and velocities the last step started from (class docstring).
        R_WK = R_WK @ so3_exp(-self._h * (R_WK.T @ w_WB))
        discrete_state.set_value(0, sensor_kinematics(
            R_WK, w_WB - self._h * alpha_W, alpha_W, A_WK.translational(), self._g_W))


# Layout of SensorKinematicsFromEncoders' discrete state: readings taken, then the window of
# [q (n), wrench (6)] rows, oldest first.
_TAKEN = 0


class SensorKinematicsFromEncoders(LeafSystem):
    """The sensor frame's kinematics from the joint encoders (hardware), and the wrench delayed to
    match them.

    .. pydrake_system::

        name: SensorKinematicsFromEncoders
        input_ports:
        - joint_positions
        - wrench
        output_ports:
        - kinematics_K
        - wrench_aligned
        - valid

    Every ``period`` s the system stores ``joint_positions`` (the positions of the ``joints`` of
    ``plant``, whose other joints stay at their defaults and at rest; None: every position of the
    plant) and ``wrench`` (6) in a window of ``window`` readings (discrete state; the first reading
    fills the whole window: the arm is taken to be at rest before the start). The joint positions,
    velocities and accelerations at the window's centre come from the Savitzky-Golay filter of
    ``identification.differentiation`` (degree ``order``); the plant's kinematics turn them into
    ``kinematics_K`` (9: ``[w_WK_K; alpha_WK_K; a_WKo_K - g_K]`` of ``sensor_frame``:
    ``V = J v``, ``A = J v_dot + A_bias``), and ``wrench_aligned`` (6) is the wrench read at that
    centre: both are ``(window - 1)/2`` periods old, so each sample pairs a wrench with the kinematics
    of its instant. ``wrench_delay`` (s, within half the window) is how much earlier than the joint
    positions read with it the wrench was measured (on hardware, the difference of the two sensors'
    latencies; in a discrete simulation, the plant's time step, since the reaction force is that of
    the step that started then: ``SensorKinematicsFromPlant``): the kinematics are read off the
    filter's polynomial at that instant. The two inputs are read together every ``period``, so they
    must be readings of the same cycle (in a simulation whose wrench is a sampled sensor, sample the
    joint positions alike, e.g. through a ``ZeroOrderHold`` of the same period). ``valid`` (1) is 1
    once the window holds ``window`` real readings. The plant context is a cache entry of this
    system's context.
    """

    def __init__(self, plant, sensor_frame, period: float, window: int = 11, order: int = 3,
                 joints=None, wrench_delay: float = 0.0):  # fmt: skip
        super().__init__()
        if not plant.is_finalized():
            raise ValueError("SensorKinematicsFromEncoders: the plant must be finalized")
        # One-line errors for bad settings; the kinematics at the instant the wrench was measured.
        self._W = savitzky_golay_weights(window, order, period, -wrench_delay)
        self._plant, self._frame, self._window = plant, sensor_frame, int(window)
        if joints is None:
            self._q_rows = self._v_rows = np.arange(plant.num_positions())
            if plant.num_positions() != plant.num_velocities():
                raise ValueError("SensorKinematicsFromEncoders: give the joints (the plant has quaternions)")
        else:
            self._q_rows = np.array([j.position_start() for j in joints])
            self._v_rows = np.array([j.velocity_start() for j in joints])
        self._n = len(self._q_rows)
        self._g_W = np.array(plant.gravity_field().gravity_vector())
        self._q = self.DeclareVectorInputPort("joint_positions", self._n)
        self._wrench = self.DeclareVectorInputPort("wrench", 6)
        self._state = self.DeclareDiscreteState(np.zeros(1 + self._window * (self._n + 6)))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._store)
        self.DeclareInitializationDiscreteUpdateEvent(self._store)
        self._plant_context = self.DeclareCacheEntry(
            "plant_context and joint accelerations",
            ValueProducer(allocate=lambda: AbstractValue.Make((plant.CreateDefaultContext(), np.zeros(0))),
                          calc=self._calc_plant_context),
            prerequisites_of_calc={self.xd_ticket()})  # fmt: skip
        ticket = {self._plant_context.ticket()}
        self.DeclareVectorOutputPort("kinematics_K", KINEMATICS, self._calc_kinematics,
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("wrench_aligned", 6, lambda c, o: o.SetFromVector(
            self._rows(c)[(self._window - 1) // 2, self._n:]), prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort("valid", 1, lambda c, o: o.SetAtIndex(
            0, float(self._x(c)[_TAKEN] >= self._window)), prerequisites_of_calc={self.xd_ticket()})

    def _x(self, context) -> np.ndarray:
        return context.get_discrete_state(self._state).get_value()

    def _rows(self, context) -> np.ndarray:
        return self._x(context)[1:].reshape(self._window, self._n + 6)

    def _store(self, context, discrete_state) -> None:
        x = self._x(context).copy()
        reading = np.concatenate([self._q.Eval(context), self._wrench.Eval(context)])
        rows = x[1:].reshape(self._window, self._n + 6)
        if x[_TAKEN] == 0:
            rows[:] = reading
        else:
            rows[:-1] = rows[1:].copy()
            rows[-1] = reading
        x[_TAKEN] += 1
        discrete_state.set_value(self._state, x)

    def _calc_plant_context(self, context, value) -> None:
        plant_context, _ = value.get_mutable_value()
        q, v, vdot = self._W @ self._rows(context)[:, : self._n]
        positions = self._plant.GetPositions(plant_context)
        velocities = np.zeros(self._plant.num_velocities())
        accelerations = np.zeros(self._plant.num_velocities())
        positions[self._q_rows], velocities[self._v_rows], accelerations[self._v_rows] = q, v, vdot
        self._plant.SetPositions(plant_context, positions)
        self._plant.SetVelocities(plant_context, velocities)
        value.set_value((plant_context, accelerations))

    def _calc_kinematics(self, context, output) -> None:
        plant_context, vdot = self._plant_context.Eval(context)
        plant, frame, world = self._plant, self._frame, self._plant.world_frame()
        J = plant.CalcJacobianSpatialVelocity(plant_context, JacobianWrtVariable.kV, frame, np.zeros(3),
                                              world, world)  # fmt: skip
        bias = plant.CalcBiasSpatialAcceleration(plant_context, JacobianWrtVariable.kV, frame, np.zeros(3),
                                                 world, world).get_coeffs()  # fmt: skip
        V = J @ plant.GetVelocities(plant_context)
        A = J @ vdot + bias
        R_WK = frame.CalcRotationMatrixInWorld(plant_context).matrix()
        output.SetFromVector(sensor_kinematics(R_WK, V[:3], A[:3], A[3:], self._g_W))
