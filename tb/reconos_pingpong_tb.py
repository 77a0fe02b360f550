"""The ping-pong system's test bench (paper §5.1, Tables 3 and 4): the echo and copy nodes
as hardware threads and round trips of Images through them."""

import random

from cocotb.triggers import RisingEdge

from host.reconos import Resource

from .reconos_tb import ReconosTB, slot_of

__all__ = ["IMAGE", "PingPongTB", "image", "run_round_trips"]

IMAGE = "sensor_msgs/msg/Image"




def image(size, rng, seq=0):
    return {
        "header": {"stamp": {"sec": seq, "nanosec": 7}, "frame_id": "cam"},
        "height": 1, "width": size, "encoding": "mono8", "is_bigendian": 0, "step": size,
        "data": bytes(rng.randrange(256) for _ in range(size)),
    }


class PingPongTB(ReconosTB):
    async def setup(self):
        self.ECHO = slot_of(self.params, "echo")
        self.COPY = slot_of(self.params, "copy")
        self.BAD = slot_of(self.params, "calls", h_report=0)
        await self.reset()
        rt = await self.start_runtime()
        self.echo_res = [Resource("rosnode", "echo"), Resource("rossub", "/ping"),
                         Resource("rospub", "/pong"), Resource("rosmsg", IMAGE)]
        self.copy_res = [Resource("rosnode", "copy"), Resource("rossub", "/ping_copy"),
                         Resource("rospub", "/pong_copy"), Resource("rosmsg", IMAGE),
                         Resource("rosmsg", IMAGE)]
        self.pong = self.broker.subscribe("/pong")
        self.pong_copy = self.broker.subscribe("/pong_copy")
        await rt.create_thread(self.ECHO, self.echo_res)
        await rt.create_thread(self.COPY, self.copy_res)
        return rt

    async def ping(self, topic, reply_queue, value, limit):
        """Publish ``value`` and wait for the reply; return (reply, cycles)."""
        self.broker.publish(topic, value)
        n = 0
        while not len(reply_queue):
            await RisingEdge(self.dut.aclk)
            n += 1
            assert n <= limit, (f"no reply on {topic} within {limit} cycles; delegate logs "
                                f"{dict(self.runtime.log)}, ignored {dict(self.runtime.ignored)}")
        return reply_queue.get_nowait(), n


async def run_round_trips(tb, topic, queue, sizes, seed, *, payload_only=False):
    """Ping with Images of the given payload sizes; the echo returns the whole message, the
    copy node a new message with the same payload."""
    rng = random.Random(seed)
    results = []
    for i, size in enumerate(sizes):
        value = image(size, rng, i)
        reply, cycles = await tb.ping(topic, queue, value, limit=200_000 + 40 * size)
        if payload_only:
            assert reply["data"] == value["data"], \
                f"{topic}: the payload of a {size}-byte message differs"
        else:
            assert reply == value, f"{topic}: the reply to a {size}-byte message differs"
        results.append((size, cycles))
    return results

