"""The base of the project's Python LeafSystems: pydrake's LeafSystem, without a failed
attribute lookup at every step of a MultibodyPlant."""

from pydrake.systems.framework import LeafSystem as _DrakeLeafSystem


class LeafSystem(_DrakeLeafSystem):
    """pydrake's LeafSystem, the same in every respect but one lookup.

    The Simulator asks every system for its witness functions again after each unrestricted
    update (a MultibodyPlant's step is one). For a Python system, pybind11 first looks for a
    Python override of DoGetWitnessFunctions; pydrake defines no attribute of that name, so
    each lookup raises and clears an AttributeError (~5.6 k instructions per system per step,
    scripts/bench_dynamic_plant.py). A C++ function under that name marks the method as not
    overridden once per class (pybind11's inactive-override cache): the C++ implementation
    runs, as it did, without the lookup. A subclass may still override it in Python."""

    DoGetWitnessFunctions = _DrakeLeafSystem.GetWitnessFunctions
