"""The example projects the tests and ``make lint`` use."""

from .harness import ROOT

__all__ = ["EXAMPLES", "example_cfg"]

#: every folder of examples/ with a build.cfg
EXAMPLES = sorted(p.parent.name for p in (ROOT / "examples").glob("*/build.cfg"))


def example_cfg(name):
    """The build.cfg of example project ``name``."""
    return ROOT / "examples" / name / "build.cfg"
