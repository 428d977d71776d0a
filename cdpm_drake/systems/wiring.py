"""Helpers the blocks share: a one-tick delay in C++ to hold a block's state, C++ wiring
(Selectors) to stack a block's inputs and split its result, building a block as a named
sub-diagram or flat into its parent, and fusing the flat blocks' wiring into one system."""

import re

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LinearSystem, Selector, SelectorParams, ZeroOrderHold


def unit_delay(size: int, time_step: float, initial=None):
    """x_{k+1} = u_k, y_k = x_k at period time_step (s), starting at `initial` (default 0).

    A C++ ZeroOrderHold where the start is zero (its default); otherwise a discrete
    LinearSystem (A = 0, B = C = I) whose default state is `initial`, so a default context,
    a cloned context and SetDefaultContext all start there."""
    x0 = np.zeros(size) if initial is None else np.asarray(initial, dtype=float)
    if not np.any(x0):
        delay = ZeroOrderHold(time_step, size)
    else:
        eye = np.eye(size)
        delay = LinearSystem(A=np.zeros((size, size)), B=eye, C=eye, D=np.zeros((size, size)),
                             time_period=time_step)
        delay.configure_default_state(x0)
    delay.delay_spec = (float(time_step), x0.copy())  # for fuse_delays
    return delay


def sub_diagram(target, build) -> None:
    """Build `target` (a Diagram subclass being constructed) from `build(builder)`."""
    builder = DiagramBuilder()
    build(builder)
    builder.BuildInto(target)


class FlatBlock:
    """A block's systems added straight into the parent's builder instead of a nested
    sub-diagram (a level of diagram less per tick): `build(block)` gets this object as its
    builder. The block's main system is named after the block (`name`), the others
    `name_<their name>`; its exported ports become this object's ports, to be wired by
    the parent with `connect_input` and `GetOutputPort`."""

    def __init__(self, builder, name: str, main: str, build):
        self.name, self._builder, self._main = name, builder, main
        self.inputs: dict[str, list] = {}
        self.outputs: dict[str, object] = {}
        self.systems: list[str] = []
        self.kinds: dict[str, str] = {}
        # {output name: (source port, offset)} for outputs that are a piece of another port.
        self.pieces: dict[str, tuple] = {}
        # {system name: spec} of the block's `wiring` Selectors and `unit_delay`s (see
        # fuse_wiring, fuse_delays).
        self.wirings: dict[str, tuple] = {}
        self.delays: dict[str, tuple] = {}
        # Where the exported ports are, by (system name, port index): ports of a system that
        # fuse_wiring removes must not be touched again, only their names remapped.
        self._input_at: dict[str, list] = {}
        self._output_at: dict[str, tuple] = {}
        # What the parent connected to each input: (system name, output index) of the source,
        # for drawing an input whose wiring fuse_wiring merged into another's.
        self._source_at: dict[str, tuple] = {}
        build(self)

    # The builder calls a block's build function makes.
    def AddNamedSystem(self, name, system):
        full = self.name if name == self._main else f"{self.name}_{name}"
        self.systems.append(full)
        # Its class, for drawing the block after its system is gone (fused_kernels).
        self.kinds[full] = re.sub(r"_\[.*\]$", "", type(system).__name__)
        if hasattr(system, "wiring_spec"):
            self.wirings[full] = system.wiring_spec
        if hasattr(system, "delay_spec"):
            self.delays[full] = system.delay_spec
        return self._builder.AddNamedSystem(full, system)

    def Connect(self, source, destination):
        self._builder.Connect(source, destination)

    def ExportInput(self, port, name):
        self.inputs.setdefault(name, []).append(port)
        self._input_at.setdefault(name, []).append(_where(port))

    def ExportOutput(self, port, name):
        self.outputs[name] = port
        self._output_at[name] = _where(port)

    # The block's ports, for the parent.
    def GetOutputPort(self, name):
        return self.outputs[name]

    def connect_input(self, source, name):
        for port in self.inputs[name]:
            self._builder.Connect(source, port)
        self._source_at[name] = _where(source)

    def relocate(self, old: tuple, port) -> None:
        """Every exported output and connected input's source at `old` (system name, output
        index) is now `port` (fused_kernels: a removed system's result)."""
        new = _where(port)
        for name, at in list(self._output_at.items()):
            if at == old:
                self._output_at[name], self.outputs[name] = new, port
        for name, at in list(self._source_at.items()):
            if at == old:
                self._source_at[name] = new

    def layout(self, moved=None, fused=()) -> dict:
        """{"systems": names, "inputs": {port: [(system name, input index)]}, "outputs":
        {port: (system name, output index)}}: the block in a built diagram, by names. After
        `fuse_wiring` and `fuse_delays` (`moved`: what fuse_wiring returned; `fused`: the
        names of the systems both took over), those systems are no longer among the block's
        and its ports on the wiring are where they went."""
        moved = moved or {}
        return {"systems": tuple(name for name in self.systems if name not in fused),
                # All the block's systems as built, the fused ones' parts included (for
                # drawing the block as built).
                "parts": tuple(self.systems),
                "kinds": {name: self.kinds[name] for name in self.systems
                          if name == self.name},
                "inputs": {name: [moved.get((*at, "in"), at) for at in ats]
                           for name, ats in self._input_at.items()},
                "outputs": {name: moved.get((*at, "out"), at)
                            for name, at in self._output_at.items()},
                # Where each connected input's source is now (through the fusion).
                "sources": {name: moved.get((*at, "out"), at)
                            for name, at in self._source_at.items()}}


def _where(port):
    return port.get_system().get_name(), int(port.get_index())


def wiring(inputs, outputs):
    """A C++ Selector that routes pieces of its inputs to its outputs: inputs [(name, size)],
    outputs [(name, [(input name, offset, count), ...])], each output the listed pieces in
    order. One system can stack a block's inputs and split its result (a Multiplexer and a
    Demultiplexer are a system each), and each output depends only on the inputs it reads
    (a Multiplexer's depends on every source, time included: each tick's time change
    invalidates it and everything it feeds). The spec stays on the system (`wiring_spec`)
    for `fuse_wiring`."""
    S = SelectorParams
    index = {name: k for k, (name, _) in enumerate(inputs)}
    ports = []
    for name, pieces in outputs:
        ports.append(S.OutputPortParams(name=name, selections=[
            S.OutputSelection(input_port_index=index[source], input_offset=offset + j)
            for source, offset, count in pieces for j in range(int(count))]))
    system = Selector(S(inputs=[S.InputPortParams(name=n, size=int(k)) for n, k in inputs],
                        outputs=ports))
    system.wiring_spec = (tuple((n, int(k)) for n, k in inputs),
                          tuple((n, tuple(pieces)) for n, pieces in outputs))
    return system


def stack(sizes):
    """`wiring` stacking inputs u0, u1, ... (sizes) into one output y0, as a Multiplexer."""
    names = [f"u{k}" for k in range(len(sizes))]
    return wiring(list(zip(names, sizes)), [("y0", [(n, 0, k) for n, k in zip(names, sizes)])])


def note_piece(builder, name, source, offset):
    """Note that the block's exported output `name` is `source` from `offset` on, when
    `builder` is a FlatBlock (the logger then reads the piece from `source` itself)."""
    if isinstance(builder, FlatBlock):
        builder.pieces[name] = (source, int(offset))


# The one system fuse_wiring leaves in a diagram.
FUSED_WIRING = "wiring"


def fuse_wiring(builder, wirings: dict, keep=()) -> tuple[dict, tuple]:
    """Replace the `wiring` Selectors {system name: wiring spec} of `builder` (every one
    connected, none exported) by one Selector named FUSED_WIRING that makes the same
    connections: each of its inputs is one source port (named "system.port"), each output
    one of the old outputs (named "old system.old output"), reading the same elements
    (through any chain of the old wirings feeding each other).
    Every system costs Drake work each tick whatever it computes (events, caching, time), so
    seven Selectors cost about seven times one; the values are bit for bit the same.
    Outputs that are neither connected nor in `keep` ({(system name, output index)}) go.

    Returns (moved, spec): moved {(old system name, port index, "in" | "out"):
    (FUSED_WIRING, new index)}, spec the fused Selector's `wiring_spec`."""
    connections = builder.connection_map()
    source_of, destinations = {}, {}
    for (dst, dst_k), (src, src_k) in connections.items():
        d, s = (dst.get_name(), int(dst_k)), (src.get_name(), int(src_k))
        source_of[d] = (src, int(src_k))
        destinations.setdefault(s, []).append((dst, int(dst_k)))
    # Every output element of every wiring, traced back through wiring feeding wiring to an
    # outside source: (source key "system.port", element index).
    sources, index_of, moved, resolved = {}, {}, {}, {}

    def source_key(name, k, input_name):
        if (name, k) not in source_of:
            raise ValueError(f"fuse_wiring: input {input_name!r} of {name!r} is not connected")
        src, src_k = source_of[(name, k)]
        key = f"{src.get_name()}.{src.get_output_port(src_k).get_name()}"
        if key not in sources:
            index_of[key] = len(sources)
            sources[key] = (src, src_k, src.get_output_port(src_k).size())
        return key

    def elements(name, k):
        if (name, k) not in resolved:
            ins, outs = wirings[name]
            index = {n: j for j, (n, _) in enumerate(ins)}
            out = []
            for input_name, offset, count in outs[k][1]:
                src, src_k = source_of.get((name, index[input_name]), (None, None))
                if src is not None and src.get_name() in wirings:
                    out += elements(src.get_name(), src_k)[offset:offset + count]
                else:
                    key = source_key(name, index[input_name], input_name)
                    out += [(key, offset + j) for j in range(int(count))]
            resolved[(name, k)] = out
        return resolved[(name, k)]

    outputs, targets = [], []
    for name, (ins, outs) in wirings.items():
        for k, (input_name, _) in enumerate(ins):
            src = source_of.get((name, k), (None,))[0]
            if src is None or src.get_name() not in wirings:
                moved[(name, k, "in")] = index_of[source_key(name, k, input_name)]
        for k, (output_name, _) in enumerate(outs):
            dsts = [(dst, dst_k) for dst, dst_k in destinations.get((name, k), [])
                    if dst.get_name() not in wirings]
            if not dsts and (name, k) not in keep:
                continue
            pieces = []  # consecutive elements of one source as one piece
            for key, j in elements(name, k):
                if pieces and pieces[-1][0] == key and pieces[-1][1] + pieces[-1][2] == j:
                    pieces[-1][2] += 1
                else:
                    pieces.append([key, j, 1])
            moved[(name, k, "out")] = len(outputs)
            outputs.append((f"{name}.{output_name}", [tuple(piece) for piece in pieces]))
            targets.append(dsts)
    for name in wirings:
        builder.RemoveSystem(builder.GetMutableSubsystemByName(name))
    fused = wiring([(key, size) for key, (_, _, size) in sources.items()], outputs)
    spec = fused.wiring_spec
    fused = builder.AddNamedSystem(FUSED_WIRING, fused)
    for key, (src, src_k, _) in sources.items():
        builder.Connect(src.get_output_port(src_k), fused.GetInputPort(key))
    for k, dsts in enumerate(targets):
        for dst, dst_k in dsts:
            builder.Connect(fused.get_output_port(k), dst.get_input_port(dst_k))
    return {(name, k, kind): (FUSED_WIRING, index)
            for (name, k, kind), index in moved.items()}, spec


# The one delay fuse_delays leaves in a diagram.
FUSED_DELAY = "memory"


def fuse_delays(builder, delays: dict) -> dict:
    """Replace the `unit_delay`s {system name: delay spec} of `builder` (same period, every
    one connected) by one `unit_delay` named FUSED_DELAY holding all their states, end to
    end, from their initial values, with two `wiring` Selectors to stack its input and split
    its output; returns those wirings {name: spec}, for fuse_wiring. The blocks' memories
    then change in one state update a tick instead of one each: Drake invalidates everything
    downstream of a state at every update. The values are bit for bit the same."""
    if len(delays) < 2:
        return {}
    periods = {spec[0] for spec in delays.values()}
    if len(periods) != 1:
        raise ValueError(f"fuse_delays: the delays have different periods {sorted(periods)}")
    connections = builder.connection_map()
    source_of, destinations = {}, {}
    for (dst, dst_k), (src, src_k) in connections.items():
        source_of[(dst.get_name(), int(dst_k))] = src.get_output_port(src_k)
        destinations.setdefault(src.get_name(), []).append(dst.get_input_port(dst_k))
    sizes = {name: spec[1].size for name, spec in delays.items()}
    sources = {name: source_of[(name, 0)] for name in delays}
    targets = {name: destinations.get(name, []) for name in delays}
    for name in delays:
        builder.RemoveSystem(builder.GetMutableSubsystemByName(name))
    start = np.concatenate([spec[1] for spec in delays.values()])
    memory = builder.AddNamedSystem(FUSED_DELAY, unit_delay(start.size, periods.pop(), start))
    stacked = wiring(list(sizes.items()), [("y0", [(n, 0, k) for n, k in sizes.items()])])
    offsets = np.cumsum([0] + list(sizes.values()))
    split = wiring([("u0", start.size)],
                   [(n, [("u0", int(o), k)]) for (n, k), o in zip(sizes.items(), offsets)])
    specs = {f"{FUSED_DELAY}_inputs": stacked.wiring_spec,
             f"{FUSED_DELAY}_outputs": split.wiring_spec}
    stacked = builder.AddNamedSystem(f"{FUSED_DELAY}_inputs", stacked)
    split = builder.AddNamedSystem(f"{FUSED_DELAY}_outputs", split)
    builder.Connect(stacked.get_output_port(), memory.get_input_port())
    builder.Connect(memory.get_output_port(), split.get_input_port())
    for name in delays:
        builder.Connect(sources[name], stacked.GetInputPort(name))
        for port in targets[name]:
            builder.Connect(split.GetOutputPort(name), port)
    return specs
