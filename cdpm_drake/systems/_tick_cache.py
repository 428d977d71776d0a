"""The one evaluation per tick that a block's output ports and its update event share."""

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import ValueProducer


def declare_tick_cache(system, description: str, compute, prerequisites):
    """A cache entry of `system` holding compute(context) (any Python object), recomputed only
    when one of `prerequisites` (dependency tickets) changes; read it with `.Eval(context)`."""
    return system.DeclareCacheEntry(
        description=description,
        value_producer=ValueProducer(
            allocate=AbstractValue.Make(object()).Clone,
            calc=lambda context, value: value.set_value(compute(context))),
        prerequisites_of_calc=prerequisites)
