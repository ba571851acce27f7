"""Loops: the paper's identify <-> observe loops wired from the systems, with their settings.

- ``body_detection``: tracker -> motion coincidence detector (paper §3.3), ``BodyDetectionConfig``.
- ``hand_eye``: the marker-free eye-to-hand loop (§3.4, Fig. 7), ``HandEyeConfig`` (the user's
  settings) and ``hand_eye_parts`` (every threshold, ``HandEyeParts``).
- ``payload``: the payload identification and touch loop (§3.5), ``KinestheticConfig``.
- ``identify_observe``: the rule's thresholds (``CoordinationConfig``) and the loop's wiring.
- ``coordination``: ``make_sustainable_coordination``, the loops chosen (``Loops``) as one Diagram for a
  controller.
- ``inspection``: the inspectable outputs (validity flags, uncertainty, the followed point).
- ``lcm_bridge``: ``make_lcm_bridge``, that Diagram on a robot speaking LCM.

The settings dataclasses are the scenario file's sections (``station.scenario``) and the keyword
arguments of ``make_sustainable_coordination``; each field's comment is its documentation
(``docs/scenarios.md`` is generated from them).
"""

from sustain_drake.loops.body_detection import BodyDetectionConfig
from sustain_drake.loops.coordination import Loops, camera_intrinsics, make_sustainable_coordination
from sustain_drake.loops.hand_eye import HandEyeConfig, HandEyeParts, hand_eye_parts
from sustain_drake.loops.identify_observe import CoordinationConfig
from sustain_drake.loops.payload import KinestheticConfig

__all__ = ["BodyDetectionConfig", "CoordinationConfig", "HandEyeConfig", "HandEyeParts", "KinestheticConfig",
           "Loops", "camera_intrinsics", "hand_eye_parts", "make_sustainable_coordination"]
