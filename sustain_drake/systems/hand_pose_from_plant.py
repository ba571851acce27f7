"""The hand pose ``X_WH`` and the wrist sensor pose ``X_WK`` from the joint positions, by the
forward kinematics of any MultibodyPlant (so that a user's arm needs no pose sensor)."""

from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem, ValueProducer


def parent_link(plant, body):
    """The body that the last moving joint inboard of ``body`` turns it on (welds are walked
    through); the world body when no joint between it and the world moves."""
    joints = [plant.get_joint(j) for j in plant.GetJointIndices()]
    inboard = {joint.child_body().index(): joint for joint in joints}
    while body.index() in inboard:
        joint = inboard[body.index()]
        if joint.num_positions() > 0:
            return joint.parent_body()
        body = joint.parent_body()
    return plant.world_body()


class HandPoseFromPlant(LeafSystem):
    """Forward kinematics of ``plant`` (finalized, double) at ``joint_positions``.

    .. pydrake_system::

        name: HandPoseFromPlant
        input_ports:
        - joint_positions
        output_ports:
        - X_WH
        - X_WK
        - X_WL

    ``joint_positions`` (size ``num_joints``, rad or m): the positions of ``model_instance`` if given,
    else of the whole plant (then ``plant.num_positions()`` must equal ``num_joints``); the other
    positions of the plant stay at their defaults. ``X_WH`` is the pose of ``hand_frame`` in the
    world, ``X_WK`` the pose of ``sensor_frame`` (the wrist force/torque sensor; ``hand_frame`` if
    None), ``X_WL`` the pose of the hand's parent link (``parent_link``: the body the last moving
    joint inboard of the hand turns it on). The plant context is a cache entry of this system's
    context (no state kept in Python).
    """

    def __init__(self, plant, hand_frame, sensor_frame=None, model_instance=None):
        super().__init__()
        if not plant.is_finalized():
            raise ValueError("HandPoseFromPlant: the plant must be finalized")
        self._plant, self._instance = plant, model_instance
        self._hand = hand_frame
        self._sensor = hand_frame if sensor_frame is None else sensor_frame
        n = plant.num_positions() if model_instance is None else plant.num_positions(model_instance)
        self._q = self.DeclareVectorInputPort("joint_positions", n)
        self._plant_context = self.DeclareCacheEntry(
            "plant_context",
            ValueProducer(allocate=lambda: AbstractValue.Make(plant.CreateDefaultContext()),
                          calc=self._calc_plant_context),
            prerequisites_of_calc={self._q.ticket()})  # fmt: skip
        parent = parent_link(plant, hand_frame.body()).body_frame()
        for name, frame in (("X_WH", self._hand), ("X_WK", self._sensor), ("X_WL", parent)):
            self.DeclareAbstractOutputPort(
                name, lambda: AbstractValue.Make(RigidTransform()),
                lambda context, output, frame=frame: output.set_value(
                    frame.CalcPoseInWorld(self._plant_context.Eval(context))),
                prerequisites_of_calc={self._plant_context.ticket()})  # fmt: skip

    def _calc_plant_context(self, context, value) -> None:
        plant_context = value.get_mutable_value()
        q = self._q.Eval(context)
        if self._instance is None:
            self._plant.SetPositions(plant_context, q)
        else:
            self._plant.SetPositions(plant_context, self._instance, q)
