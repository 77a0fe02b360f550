"""The "Sobel" node (paper Listing 2) in Amaranth: a service server filtering each request
image into the response.

Parameters (``Parameters = ...`` in build.cfg, or ``--param Sobel.NAME=VALUE``):

``mode``
    ``opencv`` (default): OpenCV's Sobel edge image of a ``bgr8`` image, any size from 3 x 3
    to ``max_width`` x ``max_height``; ``reconros``: the paper's per-byte-lane filter.
``max_width``, ``max_height``
    The largest image of the ``opencv`` mode (default 640 x 480).
"""

from hdl.reconos.threads import SobelServerThread


def build(ctx):
    return SobelServerThread(
        ctx.arch, h_srvs=ctx.handle("filter_server"),
        h_req=ctx.handle("filter_service_msg_req"), h_res=ctx.handle("filter_service_msg_res"),
        image_offsets=ctx.offsets("sensor_msgs/msg/Image"),
        mode=ctx.param("mode", "opencv"),
        max_width=ctx.param("max_width", 640, int),
        max_height=ctx.param("max_height", 480, int))
