"""Parameter validation shared by all rosgate components.

Every generator parameter is checked where it enters a component, and a bad value raises
:class:`ParameterError`, whose message names the parameter, the value and the allowed range.
Front ends (the command line, config readers) map :attr:`ParameterError.name` to their own
spelling of the parameter instead of checking the range a second time.
"""

__all__ = ["ParameterError", "check_int", "check_choice", "check_power_of_two", "read_as"]

#: how a value that does not read as a kind is described
_KIND_WORDS = {int: "a whole number", float: "a number", str: "text"}


def read_as(kind, text):
    """``text`` read as ``kind`` (``str``, ``int`` or ``float``); a :class:`ValueError`
    saying what it is not (``'abc' is not a whole number``) otherwise."""
    try:
        return kind(text)
    except ValueError:
        raise ValueError(f"{text!r} is not {_KIND_WORDS.get(kind, kind.__name__)}") from None


class ParameterError(ValueError):
    """A generator parameter is out of range.

    Attributes
    ----------
    name : str
        The parameter's name as the component spells it (``"pubs"``, ``"data_width"``).
    value : object
        The rejected value.
    allowed : str
        Human-readable description of the allowed values.
    """

    def __init__(self, name, value, allowed):
        self.name = name
        self.value = value
        self.allowed = allowed
        super().__init__(f"{name} must be {allowed}, not {value!r}")


def check_int(name, value, lo, hi=None, *, multiple_of=1):
    """Return ``value`` if it is an ``int`` in ``lo..hi`` (inclusive) and a multiple of
    ``multiple_of``."""
    if hi is None:
        allowed = f"an integer >= {lo}"
    else:
        allowed = f"an integer in {lo}..{hi}"
    if multiple_of != 1:
        allowed += f" and a multiple of {multiple_of}"
    if (not isinstance(value, int) or isinstance(value, bool) or value < lo or
            (hi is not None and value > hi) or value % multiple_of):
        raise ParameterError(name, value, allowed)
    return value


def check_power_of_two(name, value, lo, hi):
    """Return ``value`` if it is a power of two in ``lo..hi``."""
    if (not isinstance(value, int) or isinstance(value, bool) or value < lo or value > hi or
            value & (value - 1)):
        raise ParameterError(name, value, f"a power of two in {lo}..{hi}")
    return value


def check_choice(name, value, choices):
    """Return ``value`` if it is one of ``choices``."""
    if value not in choices:
        raise ParameterError(name, value, "one of " + ", ".join(repr(c) for c in choices))
    return value
