"""Threada: publishes on /outputtopic every image it receives on the hardware topic
"nicehwtopic" (through its 64-beat FIFO)."""


def build(ctx):
    return ctx.topic_gateway("sensor_msgs/msg/Image", from_hw=("PubData", "img_output"))
