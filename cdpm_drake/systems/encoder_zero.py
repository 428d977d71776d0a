"""The encoder-zero block (beyond the paper's Fig. 5): the encoders' readings less each
cable's stretch at the homing, so that the blocks that model elastic cables read unstretched
lengths (kernels/encoder_zero.py says why and how)."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.encoder_zero import encoder_zero_sizes, encoder_zero_tick
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block


class EncoderZeroSolve(KernelSystem):
    """encoder_zero: the encoders less the homing's stretch."""


def build_encoder_zero(builder, robot, *, home_tensions, window, time_step):
    """encoder_zero.encoder_zero_tick as a block. Inputs encoder_lengths (m, m: the plant's
    cable_lengths, zeroed by a homing) and tension_measured (m, N; NaN where there is no
    reading); outputs cable_lengths (m, m: unstretched), reconciled (1: 1 once the stretch is
    settled, from the first tick with every cable measured, else from the `window`-th tick)
    and homing_stretch (m, m: the stretch subtracted). home_tensions (m, N): the tensions the
    homing left the cables at by the statics, taken where no measured tension is."""
    m = robot.num_cables
    s = encoder_zero_sizes(m)
    params = owned(np.concatenate([[robot.dynamics.EA, float(window)],
                                   np.asarray(home_tensions, dtype=float)]))
    example = np.zeros(s["x"])
    example[:m] = 1.0
    tick = bind(encoder_zero_tick, params, example, np.empty(s["out"]))
    build_kernel_block(
        builder, EncoderZeroSolve(s["x"], s["out"], tick, (params,)),
        inputs=[("encoder_lengths", m), ("tension_measured", m)], memory=(s["memory"], None),
        outputs=[("cable_lengths", 0, m), ("reconciled", m, 1), ("homing_stretch", m + 1, m)],
        memory_at=s["memory_at"], time_step=time_step)
