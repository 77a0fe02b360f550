"""Several kernels side by side in one component (one export, one simulator build)."""

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

__all__ = ["KernelGroup"]


class KernelGroup(wiring.Component):
    """Independent components under one top; member ``<name>`` carries the ports of the
    component ``name`` (exported as ``<name>_<port>``).

    Parameters
    ----------
    components : dict[str, wiring.Component]
        Name -> component; names must be identifiers.
    """

    def __init__(self, components):
        for name in components:
            if not name.isidentifier():
                raise ValueError(f"kernel name must be an identifier, not {name!r}")
        self._components = dict(components)
        super().__init__({name: Out(c.signature) for name, c in self._components.items()})

    components = property(lambda self: dict(self._components))

    def elaborate(self, platform):
        m = Module()
        for name, component in self._components.items():
            m.submodules[name] = component
            wiring.connect(m, wiring.flipped(getattr(self, name)), component)
        return m
