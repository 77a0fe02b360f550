"""Playback of a rosbag2 into a co-simulated system's topics (``rosgate sim --play``).

:func:`plan_playback` runs before anything is built: it opens the bag (MCAP or sqlite3, a
rosbag2 folder or a single ``.mcap``/``.db3`` file, through rosbags), chooses the topics to
play (by default every bag topic the system subscribes, after ``--remap``), checks that each
carries the type the system's topic has, and reads every chosen message once, so that a bag
that cannot be read fails before minutes go into a build and nothing is half played. A message
whose bytes do not decode is a counted skip, not an error.

:class:`BagPlayer` runs inside the simulation as one more node: it publishes each message
into the system's topic when simulated time reaches the message's place in the bag (the first
message at the start, the gaps kept, divided by ``rate``: pace ``"bag"``), or as soon as every
subscriber of the topic took the one before (pace ``"fast"``). A message the hardware cannot
take (the project's ``sim.py`` ``accepts(ctx, name, value)`` gives a reason) is skipped,
logged and counted. Nodes of ``sim.py`` that check what was played read it in order with
:meth:`BagPlayer.next`.
"""

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from gen.msg.wire import WireError, decode_cdr

from .graph import absolute_name

__all__ = ["PlaybackError", "PlayPlan", "Played", "BagPlayer", "plan_playback", "parse_remap",
           "PACES", "ORIGIN"]

#: ``"bag"``: the bag's own timing (divided by the rate); ``"fast"``: the next message as
#: soon as every subscriber took the one before
PACES = ("bag", "fast")
#: the origin of what the player publishes (the broker's ``ignore_local_publications``)
ORIGIN = "rosgate_play"
#: cycles between two looks at the subscribers' queues (pace ``"fast"``) and at the system
#: after the last message
POLL_CYCLES = 100
#: after the last message, the system counts as done once every thread waits in an OS call
#: and nothing happened for this many cycles
SETTLE_CYCLES = 20_000


class PlaybackError(ValueError):
    """The bag or the play options cannot be used; the message names the option and why."""


@dataclass
class PlayPlan:
    """What :func:`plan_playback` checked: the bag, which of its topics go where, how many
    messages each has and which of them did not decode."""
    path: str
    #: bag topic -> the system's topic (ROS 2 name)
    topics: dict
    #: the system's topic -> (its build.cfg key, its type)
    targets: dict
    #: bag topic -> messages in the bag
    counts: dict
    #: bag topics not played -> why
    ignored: dict
    pace: str = "bag"
    rate: float = 1.0
    #: wall seconds to wait before the first message (``--play-delay``)
    delay: float = 0.0
    #: bag time of the first and the last chosen message (ns)
    start_ns: int = 0
    end_ns: int = 0
    #: (bag topic, index on it, reason) of each message that does not decode
    undecodable: list = field(default_factory=list)

    @property
    def total(self):
        return sum(self.counts.values())

    def to_json(self):
        return asdict(self)

    @classmethod
    def from_json(cls, data):
        return cls(**{**data, "targets": {k: tuple(v) for k, v in data["targets"].items()},
                      "undecodable": [tuple(u) for u in data["undecodable"]]})


@dataclass
class Played:
    """A message the player published: where, when and what."""
    topic: str
    value: dict
    #: system clock cycle of the publication (``ctx.now()``)
    cycle: int
    #: its time in the bag (ns)
    bag_ns: int


def parse_remap(text):
    """``FROM:=TO`` (ROS 2's remapping syntax) as two absolute topic names."""
    source, sep, target = text.partition(":=")
    if not sep:
        raise PlaybackError(f"--remap {text!r}: expected FROM:=TO (a bag topic, the system's "
                            f"topic)")
    try:
        return absolute_name(source, "--remap"), absolute_name(target, "--remap")
    except ValueError as exc:
        raise PlaybackError(str(exc)) from None


def _open(path):
    from rosbags.rosbag2 import Reader
    path = Path(path)
    if not path.exists():
        raise PlaybackError(f"--play {path}: no such file or folder")
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:
        raise PlaybackError(f"--play {path}: not a rosbag2 that rosbags can read (MCAP or "
                            f"sqlite3, a bag folder or a .mcap/.db3 file): "
                            f"{type(exc).__name__}: {exc}") from None
    return reader


def plan_playback(path, interfaces, library, *, topics=(), remaps=(), pace="bag", rate=1.0,
                  delay=0.0):
    """Check the bag at ``path`` against the system (``interfaces``: its
    :class:`~host.ros2.graph.RosInterfaces`, ``library``: its message library) and return the
    :class:`PlayPlan`.

    ``topics``: bag topics to play (default: each one whose name, after ``remaps``, is a
    topic some thread subscribes). ``remaps``: ``FROM:=TO`` texts. ``delay``: wall seconds
    before the first message (the simulation waits: DDS peers discover the bridge). Raises
    :class:`PlaybackError` naming what is wrong."""
    if pace not in PACES:
        raise PlaybackError(f"--play-pace {pace!r}: expected one of {', '.join(PACES)}")
    if not rate > 0:
        raise PlaybackError(f"--play-rate {rate!r}: expected a number above 0")
    if not delay >= 0:
        raise PlaybackError(f"--play-delay {delay!r}: expected seconds, 0 or more")
    reader = _open(path)
    try:
        plan = _plan(reader, str(Path(path).resolve()), interfaces, library, topics, remaps,
                     pace, float(rate))
    finally:
        reader.close()
    plan.delay = float(delay)
    return plan


def _plan(reader, path, interfaces, library, topics, remaps, pace, rate):
    system = interfaces.topics
    bag_types = {}
    for c in reader.connections:
        bag_types.setdefault(c.topic, c.msgtype)
    listed = ", ".join(sorted(bag_types)) or "none"
    mapping = {}
    for text in remaps:
        source, target = parse_remap(text)
        if source not in bag_types:
            raise PlaybackError(f"--remap {text}: the bag has no topic {source} (its topics: "
                                f"{listed})")
        mapping[source] = target
    wanted = []
    for name in topics:
        try:
            name = absolute_name(name, "--play-topic")
        except ValueError as exc:
            raise PlaybackError(str(exc)) from None
        if name not in bag_types:
            raise PlaybackError(f"--play-topic {name}: the bag has no such topic (its topics: "
                                f"{listed})")
        wanted.append(name)
    # named with --play-topic, else named by a remap: played even where no thread subscribes
    named = set(wanted) if wanted else set(mapping)
    chosen, ignored = {}, {}
    for source in sorted(bag_types):
        target = mapping.get(source, source)
        entry = system.get(target)
        if wanted and source not in wanted:
            ignored[source] = "not chosen with --play-topic"
            continue
        if entry is None:
            if source in named:
                option = f"--remap {source}:={target}" if source in mapping else \
                    f"--play-topic {source}"
                raise PlaybackError(f"{option}: the system has no topic {target} (its topics: "
                                    f"{', '.join(sorted(system)) or 'none'})"
                                    + ("" if source in mapping else
                                       f"; map it with --remap {source}:=TOPIC"))
            ignored[source] = f"{target} is not a topic of the system"
            continue
        if not entry.subscribers and source not in named:
            ignored[source] = f"no thread subscribes {target}"
            continue
        have = _type_name(library, bag_types[source])
        if have != entry.msgtype:
            raise PlaybackError(f"--play {path}: topic {source} of the bag carries "
                                f"{bag_types[source]}; the system's {target} is "
                                f"{entry.msgtype}")
        chosen[source] = target
    if not chosen:
        subscribed = sorted(t.name for t in system.values() if t.subscribers)
        raise PlaybackError(f"--play {path}: no topic of the bag goes into the system (the "
                            f"bag's topics: {listed}; the system subscribes "
                            f"{', '.join(subscribed) or 'nothing'}); choose one with "
                            f"--remap BAGTOPIC:=TOPIC")
    plan = PlayPlan(path, chosen, {t: (system[t].key, system[t].msgtype)
                                   for t in chosen.values()},
                    dict.fromkeys(chosen, 0), ignored, pace, rate)
    connections = [c for c in reader.connections if c.topic in chosen]
    first = None
    try:
        for connection, stamp, raw in reader.messages(connections=connections):
            first = stamp if first is None else first
            plan.end_ns = stamp
            index = plan.counts[connection.topic]
            plan.counts[connection.topic] += 1
            try:
                decode_cdr(library, system[chosen[connection.topic]].msgtype, raw,
                           padded=True)
            except (WireError, ValueError, IndexError) as exc:
                plan.undecodable.append((connection.topic, index, str(exc)))
    except Exception as exc:
        raise PlaybackError(f"--play {path}: the bag cannot be read to its end (after "
                            f"{sum(plan.counts.values())} messages): {type(exc).__name__}: "
                            f"{exc}") from None
    plan.start_ns = first or 0
    return plan


def _type_name(library, name):
    try:
        return library[name].name
    except Exception:
        return name


class BagPlayer:
    """Publishes a :class:`PlayPlan`'s messages into the simulation's broker.

    Parameters
    ----------
    plan : PlayPlan
    ctx : host.project_sim.SimContext
    accepts : callable or None
        ``accepts(ctx, name, value)`` of the project's ``sim.py``: a reason the hardware
        cannot take ``value`` on topic ``name``, or ``None``.
    settle : bool
        After the last message, wait until the system has done what it was given (every
        thread waits in an OS call and nothing happened for :data:`SETTLE_CYCLES`): a run
        without other nodes ends then.
    """

    def __init__(self, plan, ctx, accepts=None, settle=True):
        from gen.config import project_library

        from ..reconos.broker import Queue
        self.plan, self.ctx = plan, ctx
        self.library = project_library(ctx.project)
        self.accepts = accepts
        self.settle = settle
        self.played = dict.fromkeys(plan.targets, 0)
        self.skipped = []
        self.finished = False
        self._queues = {t: Queue() for t in plan.targets}
        self._answers = {}
        self._publishing = False
        self._held = False
        self._turns = Queue()
        ctx.broker.observers.append(self._observe)

    def hold(self):
        """From now on, after each message wait for :meth:`release` before the next: a node
        that checks each message's whole effect before the system gets the next one (a
        message then goes at its time in the bag or at its release, whichever is later)."""
        self._held = True

    def release(self):
        """Let the next message go (see :meth:`hold`)."""
        self._turns.put(True)

    def _observe(self, key, value):
        if not self._publishing:
            self._answers[key] = self._answers.get(key, 0) + 1

    async def next(self, topic):
        """The next :class:`Played` message on ``topic`` (the system's name) in the order
        played, waiting for it; ``None`` once the player has finished and none is left."""
        item = await self._queues[absolute_name(topic)].get()
        if item is None:
            self._queues[absolute_name(topic)].put(None)
        return item

    async def run(self):
        from rosbags.rosbag2 import Reader
        ctx, plan = self.ctx, self.plan
        total = plan.total
        done = 0
        if plan.delay:
            ctx.log(f"play: starting in {plan.delay:g} s")
            time.sleep(plan.delay)
        start = ctx.now()
        undecodable = {(t, i) for t, i, _ in plan.undecodable}
        index = dict.fromkeys(plan.topics, 0)
        with Reader(plan.path) as reader:
            connections = [c for c in reader.connections if c.topic in plan.topics]
            for connection, stamp, raw in reader.messages(connections=connections):
                source = connection.topic
                target = plan.topics[source]
                key, msgtype = plan.targets[target]
                k = index[source]
                index[source] += 1
                await self._wait_turn(start, stamp, key)
                done += 1
                ctx.progress(done, total, "messages")
                if (source, k) in undecodable:
                    self._skip(source, k, "its bytes do not decode as " + msgtype)
                    continue
                value = decode_cdr(self.library, msgtype, raw, padded=True)
                reason = self.accepts(ctx, target, value) if self.accepts else None
                if reason:
                    self._skip(source, k, f"the hardware cannot take it: {reason}")
                    continue
                self._publishing = True
                try:
                    ctx.broker.publish(key, value, ORIGIN)
                finally:
                    self._publishing = False
                self.played[target] += 1
                self._queues[target].put(Played(target, value, ctx.now(), stamp))
                if self._held:
                    await self._turns.get()
        self.finished = True
        for queue in self._queues.values():
            queue.put(None)
        ctx.log(f"play: {sum(self.played.values())} of {total} messages played"
                + (f", {len(self.skipped)} skipped" if self.skipped else ""))
        if self.settle:
            await self._settle()

    async def _wait_turn(self, start, stamp, key):
        ctx, plan = self.ctx, self.plan
        if plan.pace == "bag":
            due = start + round((stamp - plan.start_ns) * ctx.clock_mhz / 1000 / plan.rate)
            if due > ctx.now():
                await ctx.cycles(due - ctx.now())
            return
        from ..simulator import clock_cycles
        while self._untaken(key):
            await clock_cycles(ctx.cosim.dut.aclk, POLL_CYCLES)

    def _untaken(self, key):
        """Messages on topic ``key`` that a hardware thread's subscription holds and has not
        taken yet (the subscriptions of ``sim.py``'s nodes do not count: those may not run)."""
        return sum(len(r.state) for resources in self.ctx._resources.values()
                   for r in resources if r.kind == "rossub" and r.args[0] == key
                   and r.state is not None)

    def _skip(self, source, index, reason):
        self.skipped.append({"topic": source, "index": index, "reason": reason})
        self.ctx.log(f"play: message {index} of {source} skipped: {reason}")

    async def _settle(self):
        from ..simulator import clock_cycles
        cosim, ctx = self.ctx.cosim, self.ctx
        slots = set(ctx._resources)

        def activity():
            return (cosim.runtime.commands, cosim.memory_accesses, cosim.broker.events)
        last, quiet = activity(), 0
        while quiet < SETTLE_CYCLES:
            await clock_cycles(cosim.dut.aclk, POLL_CYCLES * 10)
            now = activity()
            waiting = all(s in cosim.runtime.pending for s in slots)
            if now != last or not waiting or any(
                    self._untaken(key) for key, _ in self.plan.targets.values()):
                last, quiet = now, 0
            else:
                quiet += POLL_CYCLES * 10

    def summary(self):
        """What was played and skipped, and what the system (its threads and the other
        nodes) published meanwhile, per topic as the build.cfg names it."""
        plan = self.plan
        return {"bag": plan.path, "pace": plan.pace, "rate": plan.rate,
                "messages": plan.total, "played": self.played,
                "mapping": plan.topics, "skipped": self.skipped, "ignored": plan.ignored,
                "finished": self.finished,
                "published_by_system": dict(sorted(self._answers.items()))}
