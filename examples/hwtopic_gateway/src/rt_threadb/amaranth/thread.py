"""Threadb: takes each image from the software topic /inputtopic and publishes it on the
hardware topic "nicehwtopic"."""


def build(ctx):
    return ctx.topic_gateway("sensor_msgs/msg/Image", to_hw=("SubData", "img_input"))
