"""One named Drake system per block of the paper's Fig. 5, a file each, named as the block is
in the diagram (and the blocks beyond the paper: the full pose's, the safety filter's, the
kinetostatic force's, the model monitor's); the plants in `plants/`.

A block is a small sub-diagram: one stateless LeafSystem calling the block's compiled kernel
(numba, in cdpm_drake/kernels/, bound once: kernels.call.bind) once per tick, the generic
`kernel_system.KernelSystem`; its state held by C++ primitives fed back (a one-tick delay,
wiring.unit_delay); its inputs stacked and its result split by a C++ Selector
(wiring.wiring). The admittance and the sliding average are C++ LinearSystems. In the
product diagram the blocks are added flat and their Selectors fused into one
(wiring.fuse_wiring). Contexts clone and simulations repeat exactly: nothing that changes
lives in Python.
"""
