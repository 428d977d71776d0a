"""Several blocks' kernels in one Drake callback: where one block's inputs need no result of
a later block in the same tick, their KernelSystems can be one system that calls their kernels
in sequence, each as it was bound, and passes a result one of them needs from an earlier one
inside the callback.

A Python callback costs ~18 k instructions a tick before its kernel computes anything
(scripts/bench/bench_block_cost.py); the safety blocks' three cost ~55 k of exp2's tick. The
blocks keep their ports, wiring, memories and names (the log and the overview read them as
before): only their KernelSystems go, each block's result then a piece of the fused one.
"""

import numpy as np
from pydrake.systems.framework import LeafSystem

from cdpm_drake.kernels.call import bind, owned, owned_scratch
from cdpm_drake.kernels.chain import move, put, take, view
from cdpm_drake.systems.kernel_system import KernelSystem
from cdpm_drake.systems.wiring import (FUSED_DELAY, FUSED_WIRING, FlatBlock, fuse_delays,
                                       fuse_wiring, wiring)

# The system fuse_kernels adds; its input stacking and its result's split are `wiring`
# Selectors named FUSED_KERNELS + "_inputs" and "_results" (fuse_wiring takes them over).
FUSED_KERNELS = "kernels"


class FusedKernelSystem(LeafSystem):
    """The kernels of several KernelSystems (their KernelSpecs, in order) in one callback:
    input the elements of their inputs that come from outside (stacked), output their
    results end to end. `at_in`: where each input element goes among the kernels' inputs;
    `links`: for each kernel, (sources, targets) indices of the values copied from earlier
    kernels' results into its inputs before it is called (buf: the kernels' inputs end to
    end, then their results)."""

    def __init__(self, specs, at_in, links):
        super().__init__()
        x_total = sum(s.x_size for s in specs)
        out_total = sum(s.out_size for s in specs)
        buf = owned(np.concatenate([np.zeros(x_total), np.full(out_total, np.nan)]))
        self._buf = buf  # kept alive with the views the kernels are given
        self._inputs = self.DeclareVectorInputPort("inputs", len(at_in))
        calc = _chain_callback(specs, self._inputs.Eval, buf,
                               np.asarray(at_in, dtype=np.int64), links, x_total)
        self.DeclareVectorOutputPort("result", out_total, calc,
                                     prerequisites_of_calc={self._inputs.ticket()})


def _chain_callback(specs, inputs, buf, at_in, links, x_total):
    """calc_result(context, output): the kernels' calls in order, written out as one closure
    (as kernel_system.kernel_callback writes one call): put the inputs, then per kernel its
    links' copies and its call (and its `failed` where it returns other than its `ok`), then
    take the results."""
    at_in = _owned_index(at_in)
    # The movers compiled (or loaded) now, not in the first tick; called bound, as the
    # kernels are (kernels.call.bind), on copies of the buffer.
    names = {"inputs": inputs, "buf": buf, "at_in": at_in, "x_total": x_total,
             "put": bind(put, np.zeros(at_in.size), owned(buf), at_in),
             "take": bind(take, owned(buf), x_total, np.empty(buf.size - x_total))}
    some = _owned_index([0])
    names["move"] = bind(move, owned(buf), some, some)
    lines = ["        put(inputs(context), buf, at_in)"]
    x_at, out_at = 0, x_total
    for k, spec in enumerate(specs):
        x, out = f"x_{k}", f"out_{k}"
        names[x] = view(buf, x_at, x_at + spec.x_size)
        names[out] = view(buf, out_at, out_at + spec.out_size)
        x_at, out_at = x_at + spec.x_size, out_at + spec.out_size
        sources, targets = links[k]
        if len(sources):
            names[f"source_{k}"] = _owned_index(sources)
            names[f"target_{k}"] = _owned_index(targets)
            lines.append(f"        move(buf, source_{k}, target_{k})")
        names[f"kernel_{k}"] = spec.kernel
        args = []
        for j, value in enumerate(spec.before):
            names[f"before_{k}_{j}"] = value
            args.append(f"before_{k}_{j}")
        args.append(x)
        for j, value in enumerate(spec.after):
            names[f"after_{k}_{j}"] = value
            args.append(f"after_{k}_{j}")
        call = f"kernel_{k}({', '.join(args + [out])})"
        if spec.failed is None:
            lines.append(f"        {call}")
        else:
            names[f"ok_{k}"], names[f"failed_{k}"] = spec.ok, spec.failed
            lines += [f"        status = {call}",
                      f"        if status != ok_{k}:",
                      f"            failed_{k}(status, {x}, {out})"]
    lines.append("        take(buf, x_total, output.get_mutable_value())")
    params = sorted(names)
    source = (f"def make({', '.join(params)}):\n"
              "    def calc_result(context, output):\n" + "\n".join(lines) + "\n"
              "    return calc_result\n")
    namespace = {}
    exec(source, namespace)
    return namespace["make"](**names)


def _owned_index(values):
    """An int64 index array in numba memory (no MemInfo a call, as kernels.call.owned)."""
    return owned_scratch(np.asarray(values, dtype=np.int64))


def fuse_kernels(builder, members, wirings: dict, name: str = FUSED_KERNELS):
    """Replace the KernelSystems of the FlatBlocks `members` (each block's system named after
    it), in this order, by one FusedKernelSystem `name`. Every element of a member's input is
    traced back through the `wiring` Selectors ({system name: wiring spec}): from an earlier
    member's result it is copied inside the callback, from a later one's it is an error (the
    order must follow the data flow), from elsewhere it becomes an input of the fused system.
    Every port that read a member's result reads its piece of the fused one (a `wiring`
    Selector `name`_results, one output per member; its input stacking is `name`_inputs).
    Returns ({Selector name: wiring spec} of the two, to fuse with the rest; the names of the
    systems removed)."""
    connections = builder.connection_map()
    source_of, destinations = {}, {}
    for (dst, dst_k), (src, src_k) in connections.items():
        source_of[(dst.get_name(), int(dst_k))] = (src, int(src_k))
        destinations.setdefault((src.get_name(), int(src_k)), []).append((dst, int(dst_k)))
    systems = [builder.GetMutableSubsystemByName(block.name) for block in members]
    for block, system in zip(members, systems):
        if not isinstance(system, KernelSystem):
            raise TypeError(f"fuse_kernels: {block.name!r} is not a KernelSystem")
    specs = [system.kernel_spec for system in systems]
    index = {block.name: k for k, block in enumerate(members)}
    x_start = np.cumsum([0] + [s.x_size for s in specs])
    x_total = int(x_start[-1])
    out_start = x_total + np.cumsum([0] + [s.out_size for s in specs])

    def elements(system, k):
        """(source system, output index, element) of each element of that output."""
        if system.get_name() not in wirings:
            return [(system, k, j) for j in range(system.get_output_port(k).size())]
        ins, outs = wirings[system.get_name()]
        at = {n: j for j, (n, _) in enumerate(ins)}
        out = []
        for input_name, offset, count in outs[k][1]:
            src, src_k = source_of[(system.get_name(), at[input_name])]
            out += elements(src, src_k)[offset:offset + count]
        return out

    sources, pieces, at_in, links = {}, [], [], []
    for k, (block, system) in enumerate(zip(members, systems)):
        src, src_k = source_of[(block.name, 0)]
        copied = ([], [])
        for i, (s, s_k, j) in enumerate(elements(src, src_k)):
            q = index.get(s.get_name())
            if q is not None:
                if q >= k:
                    raise ValueError(f"fuse_kernels: {block.name!r} reads {s.get_name()!r}'s "
                                     "result of the same tick, which comes later")
                copied[0].append(int(out_start[q]) + j)
                copied[1].append(int(x_start[k]) + i)
                continue
            key = f"{s.get_name()}.{s.get_output_port(s_k).get_name()}"
            sources.setdefault(key, s.get_output_port(s_k))
            if pieces and pieces[-1][0] == key and pieces[-1][1] + pieces[-1][2] == j:
                pieces[-1][2] += 1
            else:
                pieces.append([key, j, 1])
            at_in.append(int(x_start[k]) + i)
        links.append(copied)
    reads = {block.name: destinations.get((block.name, 0), []) for block in members}
    for system in systems:
        builder.RemoveSystem(system)

    fused = builder.AddNamedSystem(name, FusedKernelSystem(specs, at_in, links))
    stack = wiring([(key, port.size()) for key, port in sources.items()],
                   [("x", [tuple(p) for p in pieces])])
    split = wiring([("result", int(out_start[-1] - x_total))],
                   [(block.name, [("result", int(out_start[k]) - x_total, spec.out_size)])
                    for k, (block, spec) in enumerate(zip(members, specs))])
    specs_out = {f"{name}_inputs": stack.wiring_spec, f"{name}_results": split.wiring_spec}
    stack = builder.AddNamedSystem(f"{name}_inputs", stack)
    split = builder.AddNamedSystem(f"{name}_results", split)
    for key, port in sources.items():
        builder.Connect(port, stack.GetInputPort(key))
    builder.Connect(stack.get_output_port(), fused.get_input_port())
    builder.Connect(fused.get_output_port(), split.get_input_port())
    for block in members:
        for dst, dst_k in reads[block.name]:
            builder.Connect(split.GetOutputPort(block.name), dst.get_input_port(dst_k))
    return specs_out, {block.name: (split, k) for k, block in enumerate(members)}


# The blocks whose kernels one callback computes, in the order of the data flow: the path of
# the safety filter's command, from what it reads (the interference block's crossed pairs,
# the orientation held, the limits' command, the kinetostatic margin) to what its command
# feeds (the tension distribution, the Jacobian mapping, the tension damping), and the model
# monitor, which reads the distribution's estimate. The kinetostatic block's felt cue enters
# the admittance, which has no direct feedthrough (a tick later either way); the memories
# they read (the filter's barrier state, the limits' last command) are last tick's.
SAFETY_CHAIN = ("interference_force", "orientation_hold", "safety_limits",
                "kinetostatic_force", "safety_filter", "tension_distribution",
                "jacobian_mapping", "tension_damping", "model_monitor")


def safety_chain(blocks, plant) -> list:
    """The SAFETY_CHAIN blocks of `blocks` ({name: FlatBlock or system}) to fuse, those the
    diagram has (the paper's Fig. 5 too: its interference block, limits and mapping, so
    that what the safety blocks cost is measured against a Fig. 5 built alike); the monitor
    not where the plant's measurements it reads change with the reel command of the same
    tick (direct feedthrough: an algebraic loop through the fused callback)."""
    names = [name for name in SAFETY_CHAIN if name in blocks]
    if "model_monitor" in names and _feeds_through(plant):
        names.remove("model_monitor")
    return [blocks[name] for name in names] if len(names) > 1 else []


def _feeds_through(plant) -> bool:
    """Whether any output of the plant changes with its reel command of the same tick."""
    command = plant.GetInputPort("reel_velocity_command").get_index()
    return any(plant.HasDirectFeedthrough(command, k) for k in range(plant.num_output_ports()))


def assemble(builder, blocks, wirings: dict, *, fuse: bool, plant):
    """Build the diagram of `builder` ({name: block} its blocks, `wirings` the Selectors
    added beside them, e.g. the logger's): with `fuse`, the safety blocks' kernels fused
    (safety_chain), then the blocks' memories (fuse_delays) and wiring (fuse_wiring) each
    fused into one system. The diagram carries, for views: flat_blocks (each flat block's
    systems and ports by name), fused_wiring (which inputs each output of the fused wiring
    reads), fused_kernels (the fused callback's system and blocks) and block_order (the
    blocks and other systems as added, for drawing them in that order)."""
    flat = {name: block for name, block in blocks.items() if isinstance(block, FlatBlock)}
    owner = {system: name for name, block in flat.items() for system in block.systems}
    order = list(dict.fromkeys(owner.get(s.get_name(), s.get_name())
                               for s in builder.GetSystems()))
    moved, fused, gone, kernels = {}, None, set(), None
    if fuse:
        delays = {}
        for block in flat.values():
            wirings.update(block.wirings)
            delays.update(block.delays)
        chain = safety_chain(blocks, plant)
        # (All of them KernelSystems, or none fused: a benchmark's C++ stand-ins.)
        if chain and all(isinstance(builder.GetSubsystemByName(block.name), KernelSystem)
                         for block in chain):
            specs, results = fuse_kernels(builder, chain, wirings)
            wirings.update(specs)
            for member, (split, k) in results.items():
                for block in flat.values():
                    block.relocate((member, 0), split.get_output_port(k))
            gone |= set(results)
            kernels = {"system": FUSED_KERNELS, "blocks": [block.name for block in chain]}
        wirings.update(fuse_delays(builder, delays))
        gone |= set(wirings) | set(delays)
        exported = {at for block in flat.values() for at in block.layout()["outputs"].values()}
        moved, fused = fuse_wiring(builder, wirings, keep=exported)
    diagram = builder.Build()
    diagram.flat_blocks = {name: block.layout(moved, gone) for name, block in flat.items()}
    diagram.fused_kernels = kernels
    diagram.block_order = order
    if fused is None:
        diagram.fused_wiring = None
    else:
        inputs, outputs = fused
        index = {name: k for k, (name, _) in enumerate(inputs)}
        diagram.fused_wiring = {
            "system": FUSED_WIRING,
            "memory": FUSED_DELAY if diagram.HasSubsystemNamed(FUSED_DELAY) else None,
            "reads": {k: sorted({index[src] for src, _, _ in pieces})
                      for k, (_, pieces) in enumerate(outputs)}}
    return diagram
