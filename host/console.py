"""What the ``rosgate`` commands print: steps with a live status while they run, lines
logged by the simulation, errors on standard error, and a last line saying what was written
where. Built on rich; on a terminal the status animates, in a log file each step is one line.
"""

import contextlib
import time

from rich.console import Console as RichConsole

__all__ = ["Console", "Interrupted", "stop_on_signals", "discard_stdout"]


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM asked the command to stop (``signum``); the command ends with a
    line saying so and exit status ``128 + signum``."""

    def __init__(self, signum):
        super().__init__(signum)
        self.signum = signum

    @property
    def name(self):
        import signal
        return signal.Signals(self.signum).name


def _raise_interrupted(signum, frame):
    raise Interrupted(signum)


def stop_on_signals():
    """SIGINT and SIGTERM raise :class:`Interrupted` from here on, also in a process that was
    started with SIGINT ignored (a shell's background job)."""
    import signal
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _raise_interrupted)


class _QuietOnBrokenPipe(RichConsole):
    """A console whose reader went away (``rosgate ... | head``) ends the command quietly
    with the status of a SIGPIPE, as the plain ``print`` paths of the command line do."""

    def on_broken_pipe(self):
        discard_stdout()
        raise SystemExit(141)


def discard_stdout():
    """Point standard output at /dev/null once its reader went away, so the interpreter's
    last flush at exit does not fail on the closed pipe again."""
    import os
    import sys
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


class Console:
    """Output of one ``rosgate`` command.

    Parameters
    ----------
    prog : str
        The command, for error lines (``rosgate sim``).
    """

    def __init__(self, prog):
        self.prog = prog
        self.out = _QuietOnBrokenPipe(highlight=False, soft_wrap=True)
        self.err = RichConsole(stderr=True, highlight=False, soft_wrap=True)
        self._status = None
        self._start = time.monotonic()

    def print(self, text=""):
        self.out.print(text, markup=False)

    def error(self, text):
        self.err.print(f"{self.prog}: error: {text}", markup=False)

    @contextlib.contextmanager
    def step(self, text):
        """A step that takes a while: a status line that :meth:`progress` updates, then one
        line with the step's time."""
        start = time.monotonic()
        if self.out.is_terminal:
            with self.out.status(text, spinner="dots") as status:
                self._status = (status, text)
                try:
                    yield
                finally:
                    self._status = None
        else:
            self.print(f"-- {text}")
            yield
        self.print(f"-- {text}: done in {time.monotonic() - start:.1f} s")

    def progress(self, stage, detail):
        """Show ``detail`` on the running step's status line (nothing when not a
        terminal)."""
        if self._status is not None:
            status, text = self._status
            status.update(f"{text} ({detail})")

    def done(self, what):
        """The last line: what was written where, and the command's time."""
        self.print(f"{self.prog}: wrote {what} ({time.monotonic() - self._start:.0f} s)")
