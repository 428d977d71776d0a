"""The generic stateless block: one LeafSystem that calls one compiled kernel per tick.

Every Python LeafSystem of the controller is a `KernelSystem` (one stacked input, one
output, one kernel call); `build_kernel_block` adds one with its memory (a C++ one-tick
delay) and its wiring (one C++ Selector that stacks the block's inputs and the memory and
splits the result). The plants' steps (plants/) are not: they read the time, for the
person's force at the tick's time.
"""

import dataclasses

from pydrake.systems.framework import LeafSystem

from cdpm_drake.kernels.call import owned
from cdpm_drake.systems.wiring import note_piece, unit_delay, wiring

# The name build_kernel_block gives the KernelSystem; a flat build (FlatBlock) names that
# system after the block.
KERNEL_BLOCK_MAIN = "solve"


@dataclasses.dataclass(frozen=True)
class KernelSpec:
    """A KernelSystem's call: kernel(*before, x, *after, out), x of x_size and out of
    out_size values; a return other than `ok` calls failed(status, x, out) where failed is
    given."""

    kernel: object
    before: tuple
    after: tuple
    ok: object
    failed: object
    x_size: int
    out_size: int


class KernelSystem(LeafSystem):
    """out = kernel(*before, x, *after, out): one compiled call per tick; stateless.

    x is the input's value, out the output's; before and after are the kernel's constants
    (`owned` arrays, floats, ints, bools: the types it was bound for, kernel_call.bind).
    With `failed`, a kernel's return other than `ok` calls failed(status, x, out) (a
    fallback, or an error naming the numbers). The ports' names default to the generic
    block's; a block whose ports carry their signal's name passes those.

    .. pydrake_system::

        name: solve
        input_ports:
        - inputs (the block's inputs and memory, stacked)
        output_ports:
        - result (the block's outputs and next memory)
    """

    def __init__(self, x_size: int, out_size: int, kernel, before=(), after=(), *,
                 ok=None, failed=None, input_name="inputs", output_name="result"):
        super().__init__()
        self._inputs = self.DeclareVectorInputPort(input_name, x_size)
        # What fused_kernels.fuse_kernels needs to call this block's kernel from another's
        # callback.
        self.kernel_spec = KernelSpec(kernel, tuple(before), tuple(after), ok, failed,
                                      x_size, out_size)
        calc = kernel_callback(kernel, before, after, self._inputs.Eval, output_name,
                               ok=ok, failed=failed)
        self.DeclareVectorOutputPort(output_name, out_size, calc,
                                     prerequisites_of_calc={self._inputs.ticket()})


def kernel_callback(kernel, before, after, inputs, output_name, *, ok=None, failed=None):
    """KernelSystem's output callback calc_<output_name>(context, output): `kernel(*before,
    x, *after, out)`, x = inputs(context), out the output's value; with `failed`, then
    failed(status, x, out) where the kernel returned a status != ok.

    The callback is written out for the number of constants, as a closure over them (as
    dataclasses writes its methods): a tick then costs what a hand-written closure costs.
    The call with *before and *after, or through a functools.partial of the kernel, costs
    ~300-700 instructions more per call, and the Python tick function the blocks passed
    before ~440 more (callgrind, scripts/bench/count_instructions.py)."""
    first = [f"before_{k}" for k in range(len(before))]
    last = [f"after_{k}" for k in range(len(after))]

    def call(x, out):
        return f"kernel({', '.join(first + [x] + last + [out])})"

    if failed is None:  # no locals: the port values go straight into the call
        body = f"        {call('inputs(context)', 'output.get_mutable_value()')}\n"
    else:
        body = ("        x = inputs(context)\n"
                "        out = output.get_mutable_value()\n"
                f"        status = {call('x', 'out')}\n"
                "        if status != ok:\n"
                "            failed(status, x, out)\n")
    source = (f"def make(kernel, inputs, ok, failed, {', '.join(first + last)}):\n"
              f"    def calc_{output_name}(context, output):\n{body}"
              f"    return calc_{output_name}\n")
    namespace = {}
    exec(source, namespace)
    return namespace["make"](kernel, inputs, ok, failed, *before, *after)


def owned_geometry(robot):
    """The robot's reel points and platform attachments (m, base and platform frames) in
    numba-owned memory (kernel_call.owned), as the pose kernels take them."""
    return owned(robot.reels), owned(robot.attachments)


def build_kernel_block(builder, system, *, inputs, memory, outputs, memory_at, time_step,
                       memory_outputs=(), exported=True):
    """Add `system` (a KernelSystem) as KERNEL_BLOCK_MAIN, a one-tick delay "memory"
    (`memory`: its size and initial value, None for zeros; or None for a block without
    memory) and a Selector "wiring" to `builder` (a DiagramBuilder or a FlatBlock). inputs:
    [(port name, size)] exported, stacked in this order and then the memory; outputs:
    [(port name, offset, size)] pieces of the result exported; the next memory is the result
    from `memory_at` on; memory_outputs: [(port name, offset, size)] pieces of the memory
    (last tick's) exported. Returns the Selector (the caller connects its inputs itself with
    exported=False)."""
    solve = builder.AddNamedSystem(KERNEL_BLOCK_MAIN, system)
    result_size = system.get_output_port(0).size()
    ins = list(inputs)
    pieces = [(name, 0, size) for name, size in inputs]
    outs = [(name, [("result", offset, size)]) for name, offset, size in outputs]
    if memory is not None:
        size, initial = memory
        ins.append(("memory_previous", size))
        pieces.append(("memory_previous", 0, size))
        outs.append(("memory", [("result", memory_at, size)]))
        outs += [(name, [("memory_previous", offset, count)])
                 for name, offset, count in memory_outputs]
    ins.append(("result", result_size))
    route = builder.AddNamedSystem("wiring", wiring(ins, [("inputs", pieces)] + outs))
    result = solve.GetOutputPort("result")
    builder.Connect(result, route.GetInputPort("result"))
    builder.Connect(route.GetOutputPort("inputs"), solve.GetInputPort("inputs"))
    if memory is not None:
        delay = builder.AddNamedSystem("memory", unit_delay(memory[0], time_step, memory[1]))
        builder.Connect(route.GetOutputPort("memory"), delay.get_input_port())
        builder.Connect(delay.get_output_port(), route.GetInputPort("memory_previous"))
    if exported:  # else the caller exports (or connects) the inputs itself
        for name, _ in inputs:
            builder.ExportInput(route.GetInputPort(name), name)
    for name, offset, _ in outputs:
        builder.ExportOutput(route.GetOutputPort(name), name)
        note_piece(builder, name, result, offset)
    for name, _, _ in memory_outputs:
        builder.ExportOutput(route.GetOutputPort(name), name)
    return route
