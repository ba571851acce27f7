"""The loops' inspectable outputs wired (issue 28, item 4): ``add_inspection`` adds an
``AdoptedEstimates`` (every estimate with its validity flag and uncertainty) and, with the hand-eye
loop, a ``FollowedPoint`` (the followed tracked point, the candidates' states);
``add_estimate_overlay`` draws them in Meshcat beside the truth (``EstimateOverlay``)."""

from __future__ import annotations

from dataclasses import dataclass

from sustain_drake.loops.hand_eye import HandEyeLoop
from sustain_drake.loops.payload import PayloadLoop
from sustain_drake.systems.coordination_outputs import AdoptedEstimates, FollowedPoint
from sustain_drake.systems.estimate_overlay import EstimateOverlay, OverlayConfig


@dataclass
class Inspection:
    adopted: AdoptedEstimates
    followed: FollowedPoint | None  # with the hand-eye loop


def add_inspection(builder, hand_eye: HandEyeLoop | None, payload: PayloadLoop | None) -> Inspection:
    """Adds and connects the inspecting systems of the loops given (at least one)."""
    adopted = builder.AddSystem(AdoptedEstimates(hand_eye is not None, payload is not None))
    adopted.set_name("adopted_estimates")
    followed = None
    for prefix, loop in (("hand_eye", hand_eye), ("payload", payload)):
        if loop is not None:
            for name, port in (("solution", "adopted_solution"), ("mode", "mode")):
                target = adopted.GetInputPort(f"{prefix}_{name}")
                builder.Connect(loop.state_machine.GetOutputPort(port), target)
    if hand_eye is not None:
        candidates = hand_eye.candidates
        builder.Connect(candidates.GetOutputPort("candidates"), adopted.GetInputPort("candidates"))
        followed = builder.AddSystem(FollowedPoint(candidates.params.max_candidates))
        followed.set_name("followed_point")
        builder.Connect(candidates.GetOutputPort("candidates"), followed.GetInputPort("candidates"))
        builder.Connect(hand_eye.candidate_features(), followed.GetInputPort("tracked_features"))
        adopted_x = hand_eye.state_machine.GetOutputPort("adopted_x")
        builder.Connect(adopted_x, followed.GetInputPort("reference_x"))
    return Inspection(adopted, followed)


def add_estimate_overlay(builder, meshcat, camera_info, inspection: Inspection, X_WH, true_X_WC=None,
                         config: OverlayConfig | None = None) -> EstimateOverlay:  # fmt: skip
    """Adds an ``EstimateOverlay`` drawing the hand-eye ``inspection``'s camera and followed point
    in ``meshcat`` (frustum of ``camera_info``), the point placed by the hand pose output port
    ``X_WH``; beside the true camera from the output port ``true_X_WC`` if given."""
    overlay = builder.AddSystem(EstimateOverlay(meshcat, camera_info, config))
    overlay.set_name("estimate_overlay")
    for name in ("X_WC", "X_WC_valid"):
        builder.Connect(inspection.adopted.GetOutputPort(name), overlay.GetInputPort(name))
    for name in ("followed_point", "followed_point_valid"):
        builder.Connect(inspection.followed.GetOutputPort(name), overlay.GetInputPort(name))
    builder.Connect(X_WH, overlay.GetInputPort("X_WH"))
    if true_X_WC is not None:
        builder.Connect(true_X_WC, overlay.GetInputPort("true_X_WC"))
    return overlay
