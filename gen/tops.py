"""Exportable tops: one builder per name, shared by ``rosgate export`` and the test benches.

A builder takes keyword parameters (the same names as the component's) and returns the
component; the exported Verilog module is named after the top.
"""

from pathlib import Path

from hdl.dds import Topic
from hdl.msg import MessageCodec

__all__ = ["TOPS", "build_top"]


def build_topic(**params):
    """A :class:`hdl.dds.Topic`; see its parameters."""
    return Topic(params.pop("pubs"), params.pop("subs"), params.pop("data_width"), **params)


def message_plan(type, framing="cdr", msg_dirs=()):
    """The stream plan of ``type`` with the project message folders ``msg_dirs`` (ROS 1 store
    for the ``ros1`` framing)."""
    from gen.msg import MessageLibrary
    from gen.msg.plan import stream_plan
    store = "ros1_noetic" if framing == "ros1" else "ros2_humble"
    library = MessageLibrary([Path(d) for d in msg_dirs], store=store)
    return stream_plan(library, type, framing)


def build_msg_codec(**params):
    """A :class:`hdl.msg.MessageCodec`: ``type``, ``framing``, ``data_width``, ``msg_dirs``,
    ``max_count``."""
    plan = message_plan(params.pop("type"), params.pop("framing", "cdr"),
                        params.pop("msg_dirs", ()))
    return MessageCodec(plan, params.pop("data_width", 64), **params)


#: hardware-thread kinds of the ``reconos`` top -> thread class
def _thread_classes():
    from hdl.reconos import threads as t
    return {"echo": t.EchoThread, "copy": t.CopyThread, "calls": t.CallSequenceThread,
            "memtest": t.MemoryTestThread, "sort_service": t.SortServiceThread,
            "sort_action": t.SortActionThread, "mbox_sort": t.MailboxSortThread,
            "counter": t.SharedCounterThread, "sobel_server": t.SobelServerThread,
            "dip": t.DipThread}


def _by_kind(classes, spec, where, what):
    """``(class, parameters)`` of a ``{"kind": k, ...parameters}`` spec."""
    spec = dict(spec)
    kind = spec.pop("kind")
    if kind not in classes:
        raise ValueError(f"{where}: unknown {what} kind {kind!r}; known: "
                         f"{', '.join(sorted(classes))}")
    return classes[kind], spec


def build_thread(arch, spec, where="thread"):
    """A hardware thread from ``{"kind": k, ...parameters}`` (k a key of
    :func:`_thread_classes`)."""
    cls, params = _by_kind(_thread_classes(), spec, where, "thread")
    return cls(arch, **params)


def build_reconos(**params):
    """A :class:`hdl.reconos.ReconosSystem`: ``arch``, ``threads`` (a list of ``{"kind": k,
    ...thread parameters}`` with k a key of :func:`_thread_classes`), ``tlb_entries``,
    ``osif_depth``, ``memif_depth``, ``async_slots``."""
    from hdl.reconos import ReconosSystem
    arch = params.pop("arch", "r64")
    threads = [build_thread(arch, spec, f"threads[{i}]")
               for i, spec in enumerate(params.pop("threads"))]
    return ReconosSystem(arch, threads, **params)


def _kernel_classes():
    from hdl import kernels as k
    return {"sobel": k.Sobel, "gaussian": k.GaussianBlur, "gray": k.BgrToGray,
            "hsv": k.BgrToHsv, "inrange": k.InRange, "traffic_light": k.TrafficLightDetector,
            "equalize": k.EqualizeHist, "compensation": k.ImageCompensation, "sort": k.MergeSorter, "pid": k.PidController,
            "inverse_kinematics": k.InverseKinematics, "ball_control": k.BallControl,
            "servo_pwm": k.ServoPwm, "mnist": _mnist_cnn}


def _mnist_cnn(weights=None, **params):
    """A :class:`hdl.kernels.MnistCnn` with the weights of ``weights`` (an ``.npz`` path;
    default: the trained network of :mod:`gen.mnist`)."""
    from gen import mnist
    from hdl.kernels import MnistCnn
    return MnistCnn(mnist.load_weights(weights or mnist.WEIGHTS), **params)


def build_kernel(spec, where="kernel"):
    """A kernel from ``{"kind": k, ...parameters}`` (k a key of :func:`_kernel_classes`)."""
    cls, params = _by_kind(_kernel_classes(), spec, where, "kernel")
    return cls(**params)


def build_kernels(**params):
    """A :class:`hdl.kernels.group.KernelGroup` of ``kernels`` (name -> ``{"kind": k,
    ...parameters}``), ports ``<name>_<port>``."""
    from hdl.kernels.group import KernelGroup
    return KernelGroup({name: build_kernel(spec, f"kernels[{name!r}]")
                        for name, spec in params.pop("kernels").items()})


def build_net(**params):
    """A :class:`hdl.net.NetStack` (MAC, ARP, IPv4, ICMP, RBCP, ``sessions`` TCP sessions)."""
    from hdl.net import NetStack
    return NetStack(**params)


def build_ros1_node(**params):
    """A :class:`hdl.ros1.TcprosNode`: network engine plus TCPROS endpoints."""
    from hdl.ros1 import TcprosNode
    return TcprosNode(**params)


def _io_descriptor(io):
    """The IO descriptor of description file ``io``."""
    from gen.finemb import load_io_description
    return load_io_description(io)


def build_finemb_node(**params):
    """A :class:`hdl.finemb.FinembPidNode`: ``io`` (an IO description file), ``mac``,
    ``serial``, ``app_deadline``."""
    from hdl.finemb import FinembPidNode
    return FinembPidNode(_io_descriptor(params.pop("io")), **params)


def build_finemb_line(**params):
    """A :class:`hdl.finemb.FinembLine` of ``nodes`` PID nodes described by ``io``."""
    from hdl.finemb import FinembLine
    return FinembLine(_io_descriptor(params.pop("io")), params.pop("nodes"), **params)


def build_services(**params):
    """A :class:`gen.services.ServiceGraph`: ``server`` ("sort" or "fibonacci"), ``interface``
    (``pkg/srv/Name`` or ``pkg/action/Name``), ``msg_dirs``, ``clients`` and the server's
    parameters."""
    from gen.msg import MessageLibrary
    from gen.services import ServiceGraph, interface_plans
    library = MessageLibrary([Path(d) for d in params.pop("msg_dirs", ())], store="ros2_humble")
    plans = interface_plans(library, params.pop("interface"))
    return ServiceGraph(params.pop("server"), plans, **params)


def build_av_chain(**params):
    """A :class:`gen.av_chain.AvChain`: ``corners`` (and ``bev_corners``) of the projection
    and the :class:`~gen.av_chain.ChainConfig` fields (lists become tuples)."""
    from gen.av_chain import AvChain, chain_config

    def tuples(v):
        return tuple(tuples(x) for x in v) if isinstance(v, (list, tuple)) else v
    return AvChain(chain_config(**{k: tuples(v) for k, v in params.items()}))


#: name -> builder
TOPS = {
    "av_chain": build_av_chain,
    "services": build_services,
    "finemb_node": build_finemb_node,
    "finemb_line": build_finemb_line,
    "ros1_node": build_ros1_node,
    "net": build_net,
    "kernels": build_kernels,
    "topic": build_topic,
    "msg_codec": build_msg_codec,
    "reconos": build_reconos,
}


def build_top(name, **params):
    """Build the component of top ``name`` with ``params``."""
    try:
        builder = TOPS[name]
    except KeyError:
        raise ValueError(f"unknown top {name!r}; known: {', '.join(sorted(TOPS))}") from None
    return builder(**params)
