"""The arguments a project's ``sim.py`` takes: ``rosgate sim --arg KEY=VALUE``.

A ``sim.py`` declares them in ``ARGS``, a dict of name -> :class:`SimArg`::

    ARGS = {
        "images": SimArg("photographs to filter, comma-separated", "coffee_80x60.png",
                         files=True),
        "seed": SimArg("seed of the random scene", 1, kind=int),
    }

``rosgate sim`` then refuses a key ``ARGS`` does not name and a value its ``kind`` cannot
read, before anything is built, and lists them with ``--help-args``. Values reach the nodes
as ``ctx.args``: strings, as typed, except that a ``files`` argument names files by absolute
path when they exist relative to the folder ``rosgate`` was started in (the simulator runs in
another folder). A ``sim.py`` without ``ARGS`` receives every key unchecked.
"""

from pathlib import Path

from hdl.params import read_as

__all__ = ["SimArg", "ArgumentError", "check_args", "describe_args"]


class ArgumentError(ValueError):
    """An ``--arg`` the project's ``sim.py`` does not declare or cannot read."""


class SimArg:
    """One ``--arg`` of a ``sim.py``.

    Parameters
    ----------
    help : str
        What the argument sets, for ``--help-args``.
    default : object
        The value a node uses when the argument is not given (shown by ``--help-args``; the
        node applies it).
    kind : type
        ``str``, ``int`` or ``float``: the value must read as one (``int`` also for each item of
        a ``many`` argument).
    many : bool
        A comma-separated list of ``kind``.
    files : bool
        The value names files (comma-separated): each is made absolute against the caller's
        folder when it exists there.
    choices : sequence of str or None
        The only values accepted.
    """

    def __init__(self, help, default=None, *, kind=str, many=False, files=False, choices=None):
        if kind not in (str, int, float):
            raise TypeError(f"SimArg kind must be str, int or float, not {kind!r}")
        self.help = help
        self.default = default
        self.kind = kind
        self.many = bool(many or files)
        self.files = bool(files)
        self.choices = tuple(choices) if choices is not None else None

    def read(self, name, text):
        """Check ``text`` for ``--arg name=text``; return the value ``ctx.args`` gets."""
        items = text.split(",") if self.many else [text]
        for item in items:
            if self.choices is not None and item not in self.choices:
                raise ArgumentError(f"--arg {name}={text}: {item!r} is not one of "
                                    f"{', '.join(self.choices)}")
            try:
                read_as(self.kind, item)
            except ValueError as exc:
                raise ArgumentError(f"--arg {name}={text}: {exc}") from None
        if self.files:
            items = [str((Path.cwd() / Path(i).expanduser()).resolve())
                     if i and (Path.cwd() / Path(i).expanduser()).exists() else i
                     for i in items]
            return ",".join(items)
        return text

    def describe(self):
        kind = {str: "text", int: "whole number", float: "number"}[self.kind]
        if self.files:
            kind = "files"
        elif self.many:
            kind = f"{kind}s, comma-separated"
        if self.choices:
            kind = " | ".join(self.choices)
        default = "" if self.default is None else f"; default {self.default}"
        return f"{self.help} ({kind}{default})"


def declared_args(module):
    """``module.ARGS`` checked: a dict of :class:`SimArg` (``None`` without ``ARGS``)."""
    declared = getattr(module, "ARGS", None)
    if declared is None:
        return None
    if not isinstance(declared, dict) or not all(isinstance(v, SimArg)
                                                 for v in declared.values()):
        raise TypeError(f"{module.__file__}: ARGS must be a dict of name -> SimArg")
    return declared


def check_args(module, args, project_name="the project"):
    """Check ``args`` (key -> text) against ``module``'s ``ARGS``; return ``ctx.args``.

    Raises
    ------
    ArgumentError
        A key ``ARGS`` does not declare (the message lists the keys it does) or a value its
        argument cannot read.
    """
    if module is None:
        if args:
            raise ArgumentError(f"--arg {next(iter(args))}: {project_name} has no sim.py, so "
                                f"it takes no --arg")
        return {}
    declared = declared_args(module)
    if declared is None:
        return dict(args)
    out = {}
    for name, text in args.items():
        if name not in declared:
            known = ", ".join(sorted(declared)) or "none"
            raise ArgumentError(f"--arg {name}: {project_name}'s sim.py takes no argument "
                                f"{name!r} (it takes: {known}; see --help-args)")
        out[name] = declared[name].read(name, text)
    return out


def describe_args(module, project_name="the project"):
    """Lines for ``rosgate sim <cfg> --help-args``."""
    if module is None:
        return [f"{project_name} has no sim.py: it takes no --arg"]
    declared = declared_args(module)
    if declared is None:
        return [f"{project_name}'s sim.py declares no ARGS: every --arg KEY=VALUE reaches its "
                "nodes unchecked"]
    if not declared:
        return [f"{project_name}'s sim.py takes no --arg"]
    width = max(map(len, declared))
    return [f"--arg of {project_name} (--arg KEY=VALUE, repeatable):"] + \
        [f"  {name:<{width}}  {arg.describe()}" for name, arg in declared.items()]
