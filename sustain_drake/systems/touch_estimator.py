"""Touch estimation on the held object (paper §3.5, §4.4) as a Drake system."""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Box as DrakeBox
from pydrake.geometry import Cylinder as DrakeCylinder
from pydrake.geometry import Sphere as DrakeSphere
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem, ValueProducer

from sustain_drake.identification import payload_dynamic, touch
from sustain_drake.identification.payload import STANDARD_GRAVITY_W


def shape_from_drake(shape) -> touch.Shape:
    """The math layer's shape for a ``pydrake.geometry`` Box, Cylinder or Sphere."""
    if isinstance(shape, DrakeBox):
        return touch.Box((shape.width(), shape.depth(), shape.height()))
    if isinstance(shape, DrakeCylinder):
        return touch.Cylinder(shape.radius(), shape.length())
    if isinstance(shape, DrakeSphere):
        return touch.Sphere(shape.radius())
    raise TypeError(f"touch estimation supports Box, Cylinder and Sphere, not {type(shape).__name__}")


class TouchEstimator(LeafSystem):
    """Subtracts the identified payload's wrench and locates a touch on the held object.

    .. pydrake_system::

        name: TouchEstimator
        input_ports:
        - wrench
        - X_WK
        - payload
        - allowable_error
        - kinematics_K (optional)
        output_ports:
        - touch
        - p_KP
        - p_WP
        - f_env_W
        - residual_wrench

    ``wrench`` (6) is the sensor reading ``[tau_K; f_K]`` (the convention of
    ``identification.payload``), ``X_WK`` the sensor pose, ``payload`` the adopted payload
    solution (a ``PayloadSolution`` or a ``DynamicPayloadSolution`` from the state machine's
    ``adopted_solution``; None before one) and ``allowable_error`` (1) the state machine's
    ``sigma``. A dynamic payload's identified sensor bias is subtracted from the reading first. The
    prediction is quasi-static (the payload's weight), or, with ``kinematics_K`` connected (9:
    ``[w_WK_K; alpha_WK_K; a_WKo_K - g_K]``, rad/s, rad/s^2, m/s^2: the station's
    ``sensor_kinematics``), the Newton-Euler wrench of the payload moving with the sensor
    (``payload_dynamic.predicted_wrench``): its weight and its inertial force, and the rotational
    inertia's torque when the payload has one (a ``DynamicPayloadSolution``; a static one is a point
    mass). A fast move then is not a touch.

    A touch is declared when a payload has been adopted and the sample's error under it,
    ``s_t = ||A_t x||^2`` of the payload formulation (``= |f_c|^2/m^2 + |tau_c + f_c x p_KCm|^2``),
    exceeds ``sigma`` and the residual force is at least ``min_force`` newtons. Then ``p_KP`` /
    ``p_WP`` (m) is where the residual's line of action enters the object's shape (``shape``,
    posed by ``X_KG`` in K) and ``f_env_W`` (N) is the force the environment applies there, in
    the world. Without a touch they are zeros; ``touch`` is 1 or 0. ``residual_wrench`` (6) is
    always the reading minus the predicted payload wrench (zeros before a payload is adopted).
    Outputs are direct functions of the inputs (no state).
    """

    def __init__(self, shape, X_KG: RigidTransform | None = None, gravity_W=STANDARD_GRAVITY_W,
                 min_force: float = 0.5):  # fmt: skip
        super().__init__()
        is_ours = isinstance(shape, touch.Box | touch.Cylinder | touch.Sphere)
        self._shape = shape if is_ours else shape_from_drake(shape)
        self._X_KG = (X_KG or RigidTransform()).GetAsMatrix4()
        self._g_W = np.asarray(gravity_W, dtype=float)
        if not min_force >= 0:
            raise ValueError(f"min_force must be >= 0, got {min_force}")
        self._min_force = float(min_force)
        self._wrench = self.DeclareVectorInputPort("wrench", 6)
        self._X_WK = self.DeclareAbstractInputPort("X_WK", AbstractValue.Make(RigidTransform()))
        self._payload = self.DeclareAbstractInputPort("payload", AbstractValue.Make(None))
        self._sigma = self.DeclareVectorInputPort("allowable_error", 1)
        self._kinematics = self.DeclareVectorInputPort("kinematics_K", payload_dynamic.KINEMATICS)
        # One estimate per context, shared by all outputs: [touch, p_KP, p_WP, f_env_W, residual].
        self._estimate = self.DeclareCacheEntry(
            "touch estimate",
            ValueProducer(allocate=lambda: AbstractValue.Make(np.zeros(16)), calc=self._calc_estimate),
            {self.all_input_ports_ticket()},
        )
        for name, start, size in (("touch", 0, 1), ("p_KP", 1, 3), ("p_WP", 4, 3), ("f_env_W", 7, 3),
                                  ("residual_wrench", 10, 6)):  # fmt: skip
            self.DeclareVectorOutputPort(
                name, size, self._make_output(start, size), prerequisites_of_calc={self._estimate.ticket()}
            )

    def _make_output(self, start, size):
        def calc(context, output):
            output.SetFromVector(self._estimate.Eval(context)[start : start + size])

        return calc

    def _calc_estimate(self, context, value) -> None:
        out = np.zeros(16)
        payload = self._payload.Eval(context)
        X_WK = self._X_WK.Eval(context)
        R_WK = X_WK.rotation().matrix()
        if payload is not None and payload.mass > 0:
            wrench = self._wrench.Eval(context) - payload.bias  # a dynamic payload's sensor bias
            residual = wrench - self._predicted(context, payload, R_WK)
            out[10:16] = residual
            tau_c, f_c = residual[:3], residual[3:]
            # The static payload formulation's error s_t = ||A_t x||^2 of this sample under the
            # payload, from the residual: |f_c|^2 / m^2 + |tau_c + f_c x p_KCm|^2.
            moment = tau_c + np.cross(f_c, payload.p_KCm)
            s = float(f_c @ f_c) / payload.mass**2 + float(moment @ moment)
            sigma = float(self._sigma.Eval(context)[0])
            if s > sigma and math.sqrt(f_c @ f_c) >= self._min_force:
                point = touch.locate_touch(residual, self._shape, self._X_KG)
                if point is not None:
                    out[0] = 1.0
                    out[1:4] = point.p_KP
                    out[4:7] = X_WK.multiply(point.p_KP)
                    out[7:10] = R_WK @ point.f_env_K
        value.set_value(out)

    def _predicted(self, context, payload, R_WK) -> np.ndarray:
        """The wrench the payload alone would give: quasi-static, or moving (``kinematics_K``)."""
        if not self._kinematics.HasValue(context):
            return touch.predicted_wrench(payload.mass, payload.p_KCm, R_WK, self._g_W)
        I_Cm = getattr(payload, "I_Cm_K", np.zeros((3, 3)))
        phi = payload_dynamic.inertial_parameters(payload.mass, payload.p_KCm, I_Cm)
        return payload_dynamic.predicted_wrench(phi, np.zeros(6), self._kinematics.Eval(context))
