"""Exportable tops: one builder per name, shared by ``rosgate export`` and the test benches.

A builder takes keyword parameters (the same names as the component's) and returns the
component; the exported Verilog module is named after the top.
"""

from hdl.dds import Topic

__all__ = ["TOPS", "build_top"]


def build_topic(**params):
    """A :class:`hdl.dds.Topic`; see its parameters."""
    return Topic(params.pop("pubs"), params.pop("subs"), params.pop("data_width"), **params)


#: name -> builder
TOPS = {
    "topic": build_topic,
}


def build_top(name, **params):
    """Build the component of top ``name`` with ``params``."""
    try:
        builder = TOPS[name]
    except KeyError:
        raise ValueError(f"unknown top {name!r}; known: {', '.join(sorted(TOPS))}") from None
    return builder(**params)
