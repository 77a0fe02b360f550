"""Golden model of a hardware-mapped topic's delivery rules (docs/topics.md), for scoreboards.

Publishers tag their messages (:func:`tagged_message`) so that a subscriber's received message
names its publisher. The model checks, per subscriber, that each received message is the next
(``keep_all``) or a later (drop policies) message of that publisher, byte for byte; at the end
that nothing is missing (``keep_all``) or that every missing message is counted as a drop.
"""


__all__ = ["tagged_message", "message_publisher", "TopicScoreboard", "ScoreboardError"]


class ScoreboardError(AssertionError):
    pass


def tagged_message(pub, seq, length, rng):
    """A message of ``length`` bytes from publisher ``pub`` (< 16), its ``seq``-th.

    Byte 0 names the publisher; for messages of 3 bytes or more bytes 1-2 hold ``seq`` (little
    endian, 16 bits), shorter ones carry ``seq`` modulo 16 in byte 0's low nibble. The rest is
    random.
    """
    if not 0 <= pub < 16:
        raise ValueError(f"publisher index must be in 0..15, not {pub}")
    if length < 1:
        raise ValueError(f"message length must be >= 1, not {length}")
    if length < 3:
        head = bytes([(pub << 4) | (seq & 15)])
    else:
        head = bytes([pub, seq & 0xFF, (seq >> 8) & 0xFF])
    return head + rng.randbytes(length - len(head))


def message_publisher(message):
    """The publisher index a :func:`tagged_message` carries."""
    if len(message) < 3:
        return message[0] >> 4
    return message[0]


class TopicScoreboard:
    """Expected deliveries of one topic.

    Parameters
    ----------
    pubs, subs : int
        Endpoint counts.
    lossless : bool
        ``True`` for ``keep_all``: every subscriber must get every message.
    """

    def __init__(self, pubs, subs, *, lossless=True):
        self.pubs, self.subs = pubs, subs
        self.lossless = lossless
        self.sent = [[] for _ in range(pubs)]
        self.cursor = [[0] * pubs for _ in range(subs)]
        self.received = [[] for _ in range(subs)]
        self.skipped = [0] * subs

    def publish(self, pub, message):
        self.sent[pub].append(bytes(message))

    def deliver(self, sub, message, where=""):
        """Check one message received by subscriber ``sub``; raise :class:`ScoreboardError`."""
        message = bytes(message)
        pub = message_publisher(message) if message else -1
        if not 0 <= pub < self.pubs:
            raise ScoreboardError(f"sub {sub}{where}: message #{len(self.received[sub])} of "
                                  f"{len(message)} bytes names no publisher "
                                  f"(first bytes {message[:8].hex()}): corrupted or interleaved")
        queue = self.sent[pub]
        start = self.cursor[sub][pub]
        stop = start + 1 if self.lossless else len(queue)
        for index in range(start, min(stop, len(queue))):
            if queue[index] == message:
                self.skipped[sub] += index - start
                self.cursor[sub][pub] = index + 1
                self.received[sub].append((pub, index))
                return pub, index
        expected = queue[start] if start < len(queue) else None
        detail = ("nothing more was sent" if expected is None else
                  f"expected message {start} ({len(expected)} bytes, {expected[:8].hex()}...)")
        raise ScoreboardError(f"sub {sub}{where}: got {len(message)} bytes "
                              f"{message[:8].hex()}... from pub {pub}: {detail}; lost, "
                              "duplicated, reordered, interleaved or corrupted")

    def outstanding(self, sub):
        """Messages sent that subscriber ``sub`` has neither received nor skipped."""
        return sum(len(q) - c for q, c in zip(self.sent, self.cursor[sub]))

    def expected_count(self, sub):
        return sum(len(q) for q in self.sent)

    def check_complete(self, drops=None):
        """At the end: all delivered (lossless) or every missing message counted as a drop."""
        for sub in range(self.subs):
            missing = self.outstanding(sub) + self.skipped[sub]
            if self.lossless and missing:
                raise ScoreboardError(f"sub {sub}: {missing} messages never arrived")
            if drops is not None and drops[sub] != missing:
                raise ScoreboardError(f"sub {sub}: drop counter {drops[sub]} but "
                                      f"{missing} messages missing")


def random_lengths(rng, count, *, max_bytes, bytes_per_beat, long_share=0.1):
    """Message lengths mixing 1-beat, short, odd and long messages up to ``max_bytes``."""
    lengths = []
    for _ in range(count):
        r = rng.random()
        if r < 0.15:
            lengths.append(rng.randint(1, bytes_per_beat))
        elif r < 0.6:
            lengths.append(rng.randint(1, 4 * bytes_per_beat + 7))
        elif r < 1 - long_share:
            lengths.append(rng.randint(1, min(max_bytes, 64 * bytes_per_beat)))
        else:
            lengths.append(rng.randint(max_bytes // 2, max_bytes))
    return lengths
