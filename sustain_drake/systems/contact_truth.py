"""Ground truth of real contacts on the held tool, from the plant's contact results."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import LeafSystem

# Below this total normal force (N) the tool is not in contact (numerical dust of the solver).
_MIN_FORCE = 1e-6


def centre_of_pressure(points_W, forces_W, normals_W, weights, moments_W=None):
    """The point where the resultant of contact forces (``forces_W[i]`` applied at
    ``points_W[i]``, with couples ``moments_W[i]``, default none) meets the contact plane, and
    the resultant force, ``(p_WQ, f_W)``.

    The contact plane goes through the ``weights``-weighted centroid of the points with the
    weighted mean normal; the point returned is where the resultant's central axis crosses it,
    i.e. where the moment of all forces about the point has no component in the plane (the
    centre of pressure of a flat contact; for a single point contact, the point itself).
    """
    P = np.asarray(points_W, dtype=float).reshape(-1, 3)
    F = np.asarray(forces_W, dtype=float).reshape(-1, 3)
    w = np.asarray(weights, dtype=float)
    f = F.sum(axis=0)
    c = (w[:, None] * P).sum(axis=0) / w.sum()
    n = (w[:, None] * np.asarray(normals_W, dtype=float).reshape(-1, 3)).sum(axis=0)
    tau_c = np.cross(P - c, F).sum(axis=0)  # moment of all forces about c
    if moments_W is not None:
        tau_c = tau_c + np.asarray(moments_W, dtype=float).reshape(-1, 3).sum(axis=0)
    fn = float(n @ f)
    if np.linalg.norm(n) < 1e-12 or abs(fn) < 1e-9 * np.linalg.norm(f) * np.linalg.norm(n):
        return c, f
    # c + r with r in the plane (n.r = 0) and n x (tau_c - r x f) = 0  =>  r = n x tau_c / (n.f).
    return c + np.cross(n, tau_c) / fn, f


class ContactTruth(LeafSystem):
    """Where and how hard the world touches the held tool (evaluation only).

    .. pydrake_system::

        name: ContactTruth
        input_ports:
        - contact_results
        output_ports:
        - true_contact

    ``contact_results`` is ``MultibodyPlant.get_contact_results_output_port()``.
    ``true_contact`` (7) is ``[active, p_WQ, f_W]``: 1 while something touches the tool (else
    all zeros), the centre of pressure Q of all the tool's contacts in the world (m, see
    ``centre_of_pressure``) and the total force the environment applies on the tool in the
    world (N). Hydroelastic contacts contribute each contact polygon (its centroid, normal and
    area-weighted share of the force); point contacts their contact point.

    Args:
        tool_bodies: body indices of the held tool (as ints).
        tool_geometries: the tool's collision ``GeometryId`` values (``get_value()``), which
            identify the tool's side of a hydroelastic contact surface.
    """

    def __init__(self, tool_bodies, tool_geometries):
        super().__init__()
        self._bodies = {int(b) for b in tool_bodies}
        self._geometries = {int(g) for g in tool_geometries}
        self._results = self.DeclareAbstractInputPort("contact_results", AbstractValue.Make(ContactResults()))
        self.DeclareVectorOutputPort("true_contact", 7, self._calc)

    def contacts(self, results: ContactResults):
        """(points, forces on the tool, normals, weights, couples) of every contact on the tool,
        in W."""
        points, forces, normals, weights, moments = [], [], [], [], []
        for i in range(results.num_hydroelastic_contacts()):
            info = results.hydroelastic_contact_info(i)
            surface = info.contact_surface()
            if surface.id_M().get_value() in self._geometries:
                sign = 1.0  # F_Ac_W acts on M's body
            elif surface.id_N().get_value() in self._geometries:
                sign = -1.0
            else:
                continue
            F = info.F_Ac_W()  # at the surface's centroid
            f = sign * F.translational()
            areas = np.array([surface.area(k) for k in range(surface.num_faces())])
            face_n = np.array([surface.face_normal(k) for k in range(surface.num_faces())])
            n = (areas[:, None] * face_n).sum(axis=0)
            points.append(surface.centroid())
            forces.append(f)
            normals.append(n / max(np.linalg.norm(n), 1e-12))
            weights.append(abs(float(f @ normals[-1])) + 1e-12)
            moments.append(sign * F.rotational())
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            a, b = int(info.bodyA_index()), int(info.bodyB_index())
            if b in self._bodies:
                sign = 1.0  # contact_force is applied on body B
            elif a in self._bodies:
                sign = -1.0
            else:
                continue
            f = sign * info.contact_force()
            n = info.point_pair().nhat_BA_W
            points.append(info.contact_point())
            forces.append(f)
            normals.append(n)
            weights.append(abs(float(f @ n)) + 1e-12)
            moments.append(np.zeros(3))
        return points, forces, normals, weights, moments

    def _calc(self, context, output) -> None:
        points, forces, normals, weights, moments = self.contacts(self._results.Eval(context))
        out = np.zeros(7)
        if points:
            p, f = centre_of_pressure(points, forces, normals, weights, moments)
            if np.linalg.norm(f) > _MIN_FORCE:
                out[0], out[1:4], out[4:7] = 1.0, p, f
        output.SetFromVector(out)
