"""Recordings of a co-simulation: every message published on the project's topics, stamped
with simulated time.

:class:`BagRecorder` writes a rosbag2 (rosbags' writer, MCAP storage, metadata version 8) that
``ros2 bag info``, Foxglove and PlotJuggler open: one connection per topic with its ROS 2 type,
its message definition and RIHS01 hash, and ROS 2's default QoS; each message as the XCDR1
bytes rosbags would serialize. :class:`TraceWriter` writes one readable line per message:
simulated time, topic, type, decoded fields (long arrays shortened).
"""

from pathlib import Path

from gen.msg.wire import encode_cdr

__all__ = ["BagRecorder", "TraceWriter", "format_fields"]


def _typestore(library, msgtypes):
    """rosbags' type store of ``library``'s standard interfaces plus the project's own
    message types among ``msgtypes`` (and what they use), registered from their files."""
    from rosbags.typesys import get_types_from_msg
    store = library.typestore
    wanted = []
    for msgtype in msgtypes:
        wanted.extend(n for n in library.dependencies(msgtype) if n not in wanted)
    for name in wanted:
        if name in store.fielddefs:
            continue
        source = Path(library[name].source)
        if source.suffix != ".msg" or not source.is_file():
            raise ValueError(f"{name}: only topics of .msg types can be recorded "
                             f"(defined in {source})")
        store.register(get_types_from_msg(source.read_text(), name))
    return store


class BagRecorder:
    """A rosbag2 at ``path`` (a folder that must not exist yet) for ``topics`` (ROS 2 name
    -> type)."""

    def __init__(self, path, library, topics):
        from rosbags.rosbag2 import StoragePlugin, Writer
        self.path = Path(path)
        if self.path.exists():
            raise FileExistsError(f"--record {self.path}: the folder exists; rosbag2 writes a "
                                  f"new one")
        self.library = library
        self.topics = dict(topics)
        store = _typestore(library, self.topics.values())
        self.writer = Writer(self.path, version=8, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.connections = {
            name: self.writer.add_connection(name, library[msgtype].name, typestore=store,
                                             offered_qos_profiles=[_default_qos()])
            for name, msgtype in sorted(self.topics.items())}
        self.counts = dict.fromkeys(self.topics, 0)

    def write(self, topic, value, time_ns):
        connection = self.connections[topic]
        self.writer.write(connection, int(time_ns),
                          encode_cdr(self.library, self.topics[topic], value))
        self.counts[topic] += 1

    def close(self):
        if self.writer is not None:
            self.writer.close()
            self.writer = None


def _default_qos():
    """ROS 2's default profile (reliable, keep last 10, volatile), as rosbag2 stores it."""
    from rosbags.rosbag2.metadata import (Qos, QosDurability, QosHistory, QosLiveliness,
                                          QosReliability, QosTime)
    never = QosTime(0x7FFFFFFF, 0xFFFFFFFF)
    return Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE,
               never, never, QosLiveliness.AUTOMATIC, never, False)


def format_fields(value, limit=8):
    """``value`` (a decoded message) as ``a=1 b.c='x' data=<14400 bytes>``."""
    parts = []

    def walk(prefix, item):
        if isinstance(item, dict):
            for key, sub in item.items():
                walk(f"{prefix}{key}.", sub)
            return
        name = prefix[:-1]
        if isinstance(item, (bytes, bytearray)):
            text = f"<{len(item)} bytes>" if len(item) > limit else item.hex(" ")
        elif isinstance(item, (list, tuple)):
            if len(item) > limit or any(isinstance(x, dict) for x in item):
                text = f"<{len(item)} elements>"
            else:
                text = "[" + ", ".join(repr(x) for x in item) + "]"
        else:
            text = repr(item)
        parts.append(f"{name}={text}")
    walk("", value)
    return " ".join(parts)


class TraceWriter:
    """One line per message: ``<simulated ms> <topic> <type> <fields>``."""

    def __init__(self, path, topics):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.topics = dict(topics)
        self.file = open(self.path, "w")
        self.file.write("# simulated_ms topic type fields\n")
        self.counts = dict.fromkeys(self.topics, 0)

    def write(self, topic, value, time_ns):
        self.file.write(f"{time_ns / 1e6:.6f} {topic} {self.topics[topic]} "
                        f"{format_fields(value)}\n")
        self.counts[topic] += 1

    def close(self):
        if self.file is not None:
            self.file.close()
            self.file = None
