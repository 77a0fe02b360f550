"""A simulated design on a TAP device in a network namespace: what ``rosgate tap`` runs, and
what the tests that meet the Linux kernel use (docs/simulation.md "On a TAP device").

:class:`TapSimulation` creates the namespace and its TAP device, builds the design for
Verilator and runs it in the background with its GMII port bridged to the TAP device
(:mod:`host.tap_serve`), and removes everything when it ends. While it runs, everything in
the namespace (``ip netns exec <name> ...``: ping, tcpdump, sitcpy, your own sockets) talks to
the simulated hardware through the kernel's own network stack; so does code in the thread that
entered the context (sockets it opens are in the namespace).
"""

import json
import tempfile
import threading
import time
from pathlib import Path

from .compiled.gmii_tap import gmii_tap_harness
from .simulator import DEFAULT_CXX_OPT, run_top
from .tap import KERNEL_IP, TAP_NAME, namespace_unavailable, network_namespace

__all__ = ["TapSimulation", "TapSimulationError"]


#: the cocotb side of a design with a GMII port
SERVE = "host.tap_serve"


class TapSimulationError(RuntimeError):
    """The simulation could not start or stopped by itself; the message says why and where
    its log is."""


class TapSimulation:
    """Run ``component`` on a TAP device in a fresh network namespace.

    The GMII port goes to the TAP device through ``rosgate_gmii_tap``
    (:mod:`host.compiled.gmii_tap`), compiled into the simulator: no Python runs per byte of a
    frame. A board top (``module`` :mod:`host.tap_board_serve`) keeps its RGMII PHY models and
    the Python bridge. With no Python per byte the model sets the pace, so it is compiled at
    :data:`~host.simulator.DEFAULT_CXX_OPT`: a line of 4 FinEmbP nodes runs the Python master's
    cycles twice as fast as at -O0.

    Parameters
    ----------
    component : amaranth.lib.wiring.Component
        The design, with a GMII port named ``<port>_rxd``, ``<port>_txd`` ... in its Verilog.
    top : str
        Its Verilog module name.
    build_dir : path
        Where it is exported and built (reused while unchanged).
    port : str
        The GMII port's name prefix.
    kernel_ip, prefix : str, int
        The kernel's address on the TAP device.
    watch : list of str
        Top-level outputs to report in :attr:`status`.
    progress : callable or None
        ``progress(stage, text)`` while the simulator builds.
    ready_timeout_s : float
        How long the build and start may take.
    module : str
        The cocotb side (default :mod:`host.tap_serve`; a board top's is
        :mod:`host.tap_board_serve`).
    exported : path or None
        Verilog already written for ``top`` (``component`` is then ``None``): built with the
        bench options, not the lint options of an exported top.
    params : dict
        More parameters for the cocotb side.

    Attributes
    ----------
    namespace : str
        The namespace's name (``ip netns exec <namespace> ...``).
    """

    def __init__(self, component, top, build_dir, *, port="gmii", kernel_ip=KERNEL_IP,
                 prefix=24, watch=(), progress=None, ready_timeout_s=900,
                 module=SERVE, exported=None, params=None):
        why = namespace_unavailable()
        if why:
            raise TapSimulationError(f"cannot run on a TAP device: {why}")
        self.component, self.top = component, top
        self.build_dir = Path(build_dir)
        self.port = port
        self.kernel_ip, self.prefix = kernel_ip, prefix
        self.watch = list(watch)
        self.progress = progress
        self.ready_timeout_s = ready_timeout_s
        self.module, self.exported = module, exported
        self.params = dict(params or {})
        self.namespace = None
        self._ns = None
        self._thread = None
        self._error = None
        self._files = None

    @property
    def log_file(self):
        """The simulator's output (kept when it failed)."""
        return self.build_dir / f"tap-serve-{self.namespace}.log"

    @property
    def status(self):
        """The last status the simulation wrote: ``cycles`` (simulated), ``wall_s`` and
        ``cpu_seconds`` (the simulator process's, from the same moment on),
        ``bridge`` (frames each way) and ``signals`` (the watched outputs); ``None`` before
        the first."""
        try:
            return json.loads(self._files["status"].read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            return None

    def _run(self):
        try:
            run_top(self.module, self.top, self.component, "verilator", self.build_dir,
                    params={"port": self.port, "tap": TAP_NAME,
                            "stop_file": str(self._files["stop"]),
                            "status_file": str(self._files["status"]), "watch": self.watch,
                            **self.params},
                    log_file=self.log_file, lint=self.exported is None,
                    progress=self.progress, run_name=self.namespace, cxx_opt=DEFAULT_CXX_OPT,
                    exported=self.exported,
                    harness=gmii_tap_harness(self.port) if self.module == SERVE else None)
        except BaseException as exc:        # reported by __enter__ or stop()
            self._error = exc

    def __enter__(self):
        tmp = Path(tempfile.mkdtemp(prefix="rosgate-tap-"))
        self._files = {"stop": tmp / "stop", "status": tmp / "status.json"}
        self._ns = network_namespace(self.kernel_ip, self.prefix, TAP_NAME)
        self.namespace = self._ns.__enter__()
        # the thread is created in the namespace, and so is the simulator it starts
        self._thread = threading.Thread(target=self._run, name="rosgate-tap-sim", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + self.ready_timeout_s
        while self.status is None:
            if not self._thread.is_alive():
                self._leave()
                raise TapSimulationError(f"the simulation of {self.top} ended before it "
                                         f"started: {self._error} (log: {self.log_file})")
            if time.monotonic() > deadline:
                self.stop()
                raise TapSimulationError(f"the simulation of {self.top} did not start within "
                                         f"{self.ready_timeout_s:.0f} s (log: {self.log_file})")
            time.sleep(0.2)
        return self

    def alive(self):
        return self._thread is not None and self._thread.is_alive()

    def stop(self):
        """End the simulation and remove the namespace (also on ``__exit__``)."""
        if self._thread is not None:
            self._files["stop"].touch()
            self._thread.join(timeout=120)
            self._thread = None
            if self._error is None:
                self.log_file.unlink(missing_ok=True)
        self._leave()

    def _leave(self):
        if self._ns is not None:
            self._ns.__exit__(None, None, None)
            self._ns = None

    def __exit__(self, *exc):
        self.stop()
        return False
