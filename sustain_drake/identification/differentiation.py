"""Joint velocities and accelerations from sampled encoder positions: a Savitzky-Golay filter (pure
numpy). The dynamic payload identification needs the wrist sensor's angular acceleration and linear
acceleration; on hardware they come from the joint encoders, differentiated twice, and this is the
filter (``systems.sensor_kinematics.SensorKinematicsFromEncoders`` runs it on a Drake plant).

Over a window of ``w`` (odd) samples ``q_k`` taken every ``h`` seconds, the least-squares polynomial
of degree ``d`` (Savitzky and Golay, Anal. Chem. 36 (1964); here solved directly)::

    q(t) ~ c_0 + c_1 t + ... + c_d t^d,   t_k = (k - (w - 1)/2) h,   c = V^+ q    (V_kj = t_k^j)

gives at the window's centre ``q = c_0``, ``q_dot = c_1``, ``q_ddot = 2 c_2``: linear in the samples,
``[q; q_dot; q_ddot] = W q_window`` with fixed weights ``W`` (3 x w). The estimate is exact for any
polynomial motion of degree <= d, and it refers to the centre sample, ``(w - 1)/2`` samples in the
past: a fixed delay, so the wrench must be delayed alike (the system does). The polynomial can be
read at another instant of the window too (``at``, from the centre), e.g. where a wrench read
with the encoders was actually measured when the two sensors' latencies differ. White position noise of
standard deviation ``s`` gives ``s |W_i|`` on each estimate (``noise_gains``): at 100 Hz, ``w = 11``
and ``d = 3`` (the defaults of the loop), a quantisation of 2^-17 turn (4.8e-5 rad, about 1.4e-5 rad
RMS) gives 0.34 mrad/s and 0.01 rad/s^2.

Every public function raises ``IdentificationError`` (a ``ValueError``) with a one-line message for an
argument of the wrong type, shape or value.
"""

from __future__ import annotations

import numpy as np

from sustain_drake.identification.errors import IdentificationError, integer, real_array, real_number


def savitzky_golay_weights(window: int, order: int, period: float, at: float = 0.0) -> np.ndarray:
    """``W`` (3 x ``window``): ``[q; q_dot; q_ddot]`` at ``at`` seconds from the window's centre (0:
    the centre; negative: earlier) is ``W @ samples`` for ``window`` samples (oldest first) taken every
    ``period`` s, fitted by a polynomial of degree ``order``. IdentificationError unless ``window``
    is odd, ``2 <= order < window``, ``period`` is positive and ``at`` within the window."""
    window = integer("window", window, 3)
    if window % 2 == 0:
        raise IdentificationError(f"window must be an odd number of samples (a centre), got {window}")
    order = integer("order", order, 2, window - 1)
    period = real_number("period", period, what="a positive number of seconds")
    if not period > 0.0:
        raise IdentificationError(f"period must be a positive number of seconds, got {period}")
    at = real_number("at", at, what="a number of seconds")
    half = (window - 1) / 2 * period
    if not abs(at) <= half:
        raise IdentificationError(f"at must be within the window (|at| <= {half:g} s), got {at}")
    t = (np.arange(window) - (window - 1) / 2) * period - at  # the polynomial's variable: 0 at ``at``
    coefficients = np.linalg.pinv(np.vander(t, order + 1, increasing=True))  # c = V^+ q
    return np.vstack([coefficients[0], coefficients[1], 2.0 * coefficients[2]])


def noise_gains(window: int, order: int, period: float) -> np.ndarray:
    """The standard deviations of ``q``, ``q_dot``, ``q_ddot`` per unit standard deviation of white
    noise on the samples (the rows' norms of ``savitzky_golay_weights``)."""
    return np.linalg.norm(savitzky_golay_weights(window, order, period), axis=1)


def joint_derivatives(samples, period: float, order: int = 3) -> np.ndarray:
    """``[q; q_dot; q_ddot]`` (3 x n) at the centre of ``samples`` (window x n, oldest first, odd
    window) taken every ``period`` s, by ``savitzky_golay_weights``. IdentificationError unless
    ``samples`` is a finite real (window x n) array of an odd window and ``2 <= order < window``."""
    samples = real_array("samples", samples, (None, None), what="a (window, n) array")
    return savitzky_golay_weights(samples.shape[0], order, period) @ samples
