"""Drake lcmt messages -> the coordination's sensor inputs (for the LCM bridge of
``sustainable_coordination.make_lcm_bridge``). Joint status and images use Drake's own receivers
(``IiwaStatusReceiver``, ``LcmImageArrayToImages``); these fill the two gaps."""

from __future__ import annotations

import numpy as np
from drake import lcmt_force_torque, lcmt_image, lcmt_image_array
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem


class ForceTorqueToWrench(LeafSystem):
    """An ``lcmt_force_torque`` message as the wrench ``[tau_K; f_K]`` (N m, N).

    .. pydrake_system::

        name: ForceTorqueToWrench
        input_ports:
        - lcmt_force_torque
        output_ports:
        - wrench

    ``sign`` = +1 if the sensor reports the wrench the wrist applies on the held side (the
    convention of ``identification.payload``), -1 if it reports the wrench the held side applies on
    the sensor. A non-finite reading is passed on as zeros (no NaN into the identifiers; the
    payload identifier skips only non-finite samples, so a broken sensor shows as a change).
    """

    def __init__(self, sign: float = 1.0):
        super().__init__()
        if sign not in (1.0, -1.0):
            raise ValueError(f"ForceTorqueToWrench: sign must be +1 or -1, not {sign}")
        self._sign = float(sign)
        self._message = self.DeclareAbstractInputPort(
            "lcmt_force_torque", AbstractValue.Make(lcmt_force_torque()))  # fmt: skip
        self.DeclareVectorOutputPort("wrench", 6, self._calc)

    def _calc(self, context, output) -> None:
        m = self._message.Eval(context)
        wrench = self._sign * np.array([m.tx, m.ty, m.tz, m.fx, m.fy, m.fz], dtype=float)
        output.SetFromVector(np.where(np.isfinite(wrench), wrench, 0.0))


class ImageArrayTime(LeafSystem):
    """The capture time of an ``lcmt_image_array`` (``header.utime``, us) in seconds, for the
    tracker's ``image_time`` (so that a frame held by the subscriber is not processed twice).

    .. pydrake_system::

        name: ImageArrayTime
        input_ports:
        - lcmt_image_array
        output_ports:
        - image_time

    Also refuses (ValueError, one line) an uncompressed depth image: Drake 1.51.1's
    ``LcmImageArrayToImages`` copies one byte per pixel of an uncompressed image, i.e. only the
    first quarter of a float depth image (half of a 16-bit one), and leaves the rest zero; its zlib
    path is right. Publish with ``ImageToLcmImageArrayT(do_compress=True)``.
    """

    def __init__(self):
        super().__init__()
        self._message = self.DeclareAbstractInputPort(
            "lcmt_image_array", AbstractValue.Make(lcmt_image_array()))  # fmt: skip
        self.DeclareVectorOutputPort("image_time", 1, self._calc)

    def _calc(self, context, output) -> None:
        message = self._message.Eval(context)
        raw = lcmt_image.COMPRESSION_METHOD_NOT_COMPRESSED
        for image in message.images:
            if image.pixel_format == lcmt_image.PIXEL_FORMAT_DEPTH and image.compression_method == raw:
                raise ValueError("lcmt_image_array: an uncompressed depth image is decoded wrongly by "
                                 "Drake's LcmImageArrayToImages; publish it zlib-compressed")  # fmt: skip
        output.SetAtIndex(0, 1e-6 * message.header.utime)
