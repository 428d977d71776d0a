"""The force-sensor source of Fig. 5: sensor range and the sliding-average filter."""

import math

import numpy as np
from pydrake.systems.framework import LeafSystem


def clip_to_sensor_range(f, axis, axial_range, transverse_range) -> np.ndarray:
    """Saturate a force (N) as an FSE103 does: axial component to +-axial_range along the handle
    `axis` (unit), transverse part to transverse_range in norm."""
    # Plain floats: three components, every tick.
    fx, fy, fz = (float(c) for c in f)
    ax, ay, az = (float(c) for c in axis)
    axial = fx * ax + fy * ay + fz * az
    tx, ty, tz = fx - axial * ax, fy - axial * ay, fz - axial * az
    n = math.sqrt(tx * tx + ty * ty + tz * tz)
    if n > transverse_range:
        k = transverse_range / n
        tx, ty, tz = tx * k, ty * k, tz * k
    axial = min(max(axial, -axial_range), axial_range)
    return np.array([axial * ax + tx, axial * ay + ty, axial * az + tz])


class ForceSensorSource(LeafSystem):
    """The operator's hand force F_H in the base frame, as the controller sees it.

    The raw sample (simulated operator or the real sensor, via the plant's `measured_force`)
    is saturated to the sensor's range, then averaged over the last `window` samples (the
    sliding-average filter of section 5). The window lives in discrete state.

    .. pydrake_system::

        name: force_sensor
        input_ports:
        - measured_force (N, base frame)
        output_ports:
        - F_H (N, base frame)
    """

    def __init__(self, *, axial_axis, axial_range=100.0, transverse_range=80.0, window=10,
                 time_step=0.002):
        super().__init__()
        axis = np.asarray(axial_axis, dtype=float)
        self._axis = axis / np.linalg.norm(axis)
        self._axial_range = float(axial_range)
        self._transverse_range = float(transverse_range)
        self._window = int(window)
        self._measured = self.DeclareVectorInputPort("measured_force", 3)
        # The last window-1 clipped samples, oldest first (3 per sample).
        self._history = self.DeclareDiscreteState(3 * (self._window - 1))
        self.DeclareVectorOutputPort(
            "F_H", 3, self._calc_F_H,
            prerequisites_of_calc={self._measured.ticket(),
                                   self.discrete_state_ticket(self._history)})
        if self._window > 1:
            self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0, self._update_history)

    def _clipped(self, context):
        return clip_to_sensor_range(self._measured.Eval(context), self._axis,
                                    self._axial_range, self._transverse_range)

    def _calc_F_H(self, context, output):
        f = self._clipped(context)
        if self._window > 1:
            past = context.get_discrete_state(self._history).get_value().reshape(-1, 3)
            f = (past.sum(axis=0) + f) / self._window
        output.SetFromVector(f)

    def _update_history(self, context, discrete_state):
        past = context.get_discrete_state(self._history).get_value()
        new = np.concatenate([past[3:], self._clipped(context)])
        discrete_state.get_mutable_vector(self._history).SetFromVector(new)
