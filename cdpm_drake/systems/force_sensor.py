"""The force-sensor source of Fig. 5: sensor range and the sliding-average filter."""

import numpy as np
from pydrake.systems.framework import Diagram
from pydrake.systems.primitives import LinearSystem

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.force_sensor import clip_into, clip_to_sensor_range
from cdpm_drake.systems.kernel_system import KernelSystem
from cdpm_drake.systems.wiring import sub_diagram

__all__ = ["ForceSensorSource", "SensorRange", "clip_to_sensor_range", "sliding_average"]


class SensorRange(KernelSystem):
    """The sensor's measuring range (`force_sensor.clip_to_sensor_range`), per sample;
    stateless.

    .. pydrake_system::

        name: sensor_range
        input_ports:
        - measured_force (N, base frame)
        output_ports:
        - clipped_force (N, base frame)
    """

    def __init__(self, *, axial_axis, axial_range, transverse_range):
        axis = np.asarray(axial_axis, dtype=float)
        axis = owned(axis / np.linalg.norm(axis))
        axial, transverse = float(axial_range), float(transverse_range)
        # Compiled (or loaded) now, not in the first tick.
        clip = bind(clip_into, np.zeros(3), axis, axial, transverse, np.empty(3))
        super().__init__(3, 3, clip, after=(axis, axial, transverse),
                         input_name="measured_force", output_name="clipped_force")


def sliding_average(window: int, time_step: float) -> LinearSystem:
    """The average of the last `window` samples as a discrete FIR LinearSystem (3 axes):
    the state holds the previous window - 1 samples, oldest first; y_k = (x_k sum + u_k) / W
    (direct feedthrough: the sample of tick k counts at tick k)."""
    W = int(window)
    n = 3 * (W - 1)
    A = np.zeros((n, n))
    A[:n - 3, 3:] = np.eye(n - 3)  # shift: drop the oldest sample
    B = np.zeros((n, 3))
    B[n - 3:] = np.eye(3)           # the newest sample enters last
    C = np.tile(np.eye(3), W - 1) / W
    D = np.eye(3) / W
    return LinearSystem(A=A, B=B, C=C, D=D, time_period=time_step)


class ForceSensorSource(Diagram):
    """The operator's hand force F_H in the base frame, as the controller sees it.

    The raw sample (simulated operator or the real sensor, via the plant's `measured_force`)
    is saturated to the sensor's range (`sensor_range`, exact), then averaged over the last
    `window` samples (`sliding_average`: the filter of section 5, a C++ FIR whose state is
    the window).

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
        sub_diagram(self, lambda builder: build_force_sensor(
            builder, axial_axis=axial_axis, axial_range=axial_range,
            transverse_range=transverse_range, window=window, time_step=time_step))


# The system a flat build (FlatBlock) names after the block.
FORCE_SENSOR_MAIN = "sensor_range"


def build_force_sensor(builder, *, axial_axis, axial_range=100.0, transverse_range=80.0,
                       window=10, time_step=0.002):
    """ForceSensorSource's systems and exported ports, into `builder` (a DiagramBuilder or
    a FlatBlock)."""
    clip = builder.AddNamedSystem("sensor_range", SensorRange(
        axial_axis=axial_axis, axial_range=axial_range, transverse_range=transverse_range))
    builder.ExportInput(clip.GetInputPort("measured_force"), "measured_force")
    out = clip.GetOutputPort("clipped_force")
    if int(window) > 1:
        fir = builder.AddNamedSystem("sliding_average", sliding_average(window, time_step))
        builder.Connect(out, fir.get_input_port())
        out = fir.get_output_port()
    builder.ExportOutput(out, "F_H")
