"""Image thresholds for any camera: every pixel setting is stated for the camera the results were
measured with (640 x 480, 45 deg vertical field of view, f = 579.4 px) and scaled by the camera's
focal length over that one, so a threshold means the same angle of the scene at any resolution
(a window over a texture holds the same patch, a flow threshold the same angular speed)."""

import dataclasses
import math

# rad per pixel of the measured camera: tan(22.5 deg) / 240 px.
RAD_PER_PX_MEASURED = math.tan(math.radians(22.5)) / 240.0
# px: the smallest window a scaled one becomes (a Lucas-Kanade or corner window needs a few pixels).
MIN_WINDOW = 3


def pixel_scale(info) -> float:
    """A camera's pixels per measured-camera pixel: its focal length (``CameraInfo.focal_x()``,
    px) times ``RAD_PER_PX_MEASURED``; 1 at the measured camera."""
    return info.focal_x() * RAD_PER_PX_MEASURED


def scaled(params, scale: float, lengths=(), windows=(), odd_windows=()):
    """``params`` (a dataclass) with its pixel ``lengths`` (floats) times ``scale``, its integer
    ``windows`` (half sides, sides) rounded, and its ``odd_windows`` rounded to the nearest odd
    integer; a window shrinks to no fewer than ``MIN_WINDOW`` px (or its own size if smaller) and 0
    (off) stays 0; unchanged at ``scale == 1``."""
    if scale == 1.0:
        return params

    def window(name):
        value = getattr(params, name)
        return 0 if value == 0 else max(min(value, MIN_WINDOW), round(value * scale))

    changes = {name: getattr(params, name) * scale for name in lengths}
    changes |= {name: window(name) for name in windows}
    changes |= {name: max(MIN_WINDOW, 2 * round((getattr(params, name) * scale - 1) / 2) + 1)
                for name in odd_windows}
    return dataclasses.replace(params, **changes)
