"""Helpers the blocks share: a one-tick delay in C++ to hold a block's state, and building a
block as a named sub-diagram."""

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
        return ZeroOrderHold(time_step, size)
    eye = np.eye(size)
    delay = LinearSystem(A=np.zeros((size, size)), B=eye, C=eye, D=np.zeros((size, size)),
                         time_period=time_step)
    delay.configure_default_state(x0)
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
        # {output name: (source port, offset)} for outputs that are a piece of another port.
        self.pieces: dict[str, tuple] = {}
        self.systems: list[str] = []
        build(self)

    # The builder calls a block's build function makes.
    def AddNamedSystem(self, name, system):
        full = self.name if name == self._main else f"{self.name}_{name}"
        self.systems.append(full)
        return self._builder.AddNamedSystem(full, system)

    def Connect(self, source, destination):
        self._builder.Connect(source, destination)

    def ExportInput(self, port, name):
        self.inputs.setdefault(name, []).append(port)

    def ExportOutput(self, port, name):
        self.outputs[name] = port

    # The block's ports, for the parent.
    def GetOutputPort(self, name):
        return self.outputs[name]

    def connect_input(self, source, name):
        for port in self.inputs[name]:
            self._builder.Connect(source, port)

    def layout(self) -> dict:
        """{"systems": names, "inputs": {port: [(system name, input index)]}, "outputs":
        {port: (system name, output index)}}: the block in a built diagram, by names."""
        def where(port):
            return port.get_system().get_name(), int(port.get_index())

        return {"systems": tuple(self.systems),
                "inputs": {name: [where(p) for p in ports] for name, ports in self.inputs.items()},
                "outputs": {name: where(port) for name, port in self.outputs.items()}}



def wiring(inputs, outputs):
    """A C++ Selector that routes pieces of its inputs to its outputs: inputs [(name, size)],
    outputs [(name, [(input name, offset, count), ...])], each output the listed pieces in
    order. One system can stack a block's inputs and split its result (a Multiplexer and a
    Demultiplexer are a system each), and each output depends only on the inputs it reads
    (a Multiplexer's depends on every source, time included: each tick's time change
    invalidates it and everything it feeds)."""
    S = SelectorParams
    index = {name: k for k, (name, _) in enumerate(inputs)}
    ports = []
    for name, pieces in outputs:
        ports.append(S.OutputPortParams(name=name, selections=[
            S.OutputSelection(input_port_index=index[source], input_offset=offset + j)
            for source, offset, count in pieces for j in range(int(count))]))
    return Selector(S(inputs=[S.InputPortParams(name=n, size=int(k)) for n, k in inputs],
                      outputs=ports))


def stack(sizes):
    """`wiring` stacking inputs u0, u1, ... (sizes) into one output y0, as a Multiplexer."""
    names = [f"u{k}" for k in range(len(sizes))]
    return wiring(list(zip(names, sizes)), [("y0", [(n, 0, k) for n, k in zip(names, sizes)])])


def note_piece(builder, name, source, offset):
    """Note that the block's exported output `name` is `source` from `offset` on, when
    `builder` is a FlatBlock (the logger then reads the piece from `source` itself)."""
    if isinstance(builder, FlatBlock):
        builder.pieces[name] = (source, int(offset))
