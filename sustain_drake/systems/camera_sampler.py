"""Samples an RGB-D camera once per frame (zero-order hold), with range-dependent depth noise."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import ImageDepth32F, ImageLabel16I, ImageRgba8U

from sustain_drake.systems.depth_noise import DepthNoiseModel

_IMAGE_TYPES = {"color_image": ImageRgba8U, "depth_image": ImageDepth32F,
                "label_image": ImageLabel16I}


class RgbdCameraSampler(LeafSystem):
    """Holds the images of a (continuous) ``RgbdSensor`` sampled at ``fps``.

    .. pydrake_system::

        name: RgbdCameraSampler
        input_ports:
        - color_image (optional)
        - depth_image (optional)
        - label_image (optional)
        output_ports:
        - color_image (optional)
        - depth_image (optional)
        - label_image (optional)
        - image_time

    Only the images named in ``images`` get ports, and only those are rendered, once per
    frame at t = k / fps (unlike ``RgbdSensorDiscrete``, which also renders a 16-bit depth
    image). The images and their capture time ``image_time`` (s) are abstract and discrete
    state, so contexts can be cloned. With a ``depth_noise`` model, frame k's depth noise is
    drawn from a generator seeded with ``(seed, k)``.
    """

    def __init__(self, fps: float, images=("color_image", "depth_image"),
                 depth_noise: DepthNoiseModel | None = None, seed: int = 0):
        super().__init__()
        if not fps > 0:
            raise ValueError(f"fps must be > 0, got {fps}")
        unknown = set(images) - set(_IMAGE_TYPES)
        if unknown or not images:
            raise ValueError(f"images must be a non-empty subset of {sorted(_IMAGE_TYPES)}")
        self._fps = float(fps)
        self._noise = depth_noise
        self._seed = int(seed)
        self._names = [name for name in _IMAGE_TYPES if name in images]
        self._inputs = {}
        self._states = {}
        for name in self._names:
            model = AbstractValue.Make(_IMAGE_TYPES[name]())
            self._inputs[name] = self.DeclareAbstractInputPort(name, model)
            self._states[name] = self.DeclareAbstractState(model)
            self.DeclareStateOutputPort(name, self._states[name])
        self._time = self.DeclareDiscreteState(1)
        self.DeclareStateOutputPort("image_time", self._time)
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0 / self._fps, 0.0, self._sample)
        # Images right from the start, so nobody reads an empty (0 x 0) image.
        self.DeclareInitializationUnrestrictedUpdateEvent(self._sample)

    def _sample(self, context, state) -> None:
        t = context.get_time()
        for name in self._names:
            image = self._inputs[name].Eval(context)
            if name == "depth_image" and self._noise is not None:
                frame = int(np.floor(t * self._fps + 1e-6))
                rng = np.random.default_rng([self._seed, frame])
                noisy = ImageDepth32F(image.width(), image.height())
                self._noise.apply(image.data, rng, out=noisy.mutable_data)  # straight into the image
                image = noisy
            state.get_mutable_abstract_state(int(self._states[name])).set_value(image)
        state.get_mutable_discrete_state(self._time).set_value([t])
