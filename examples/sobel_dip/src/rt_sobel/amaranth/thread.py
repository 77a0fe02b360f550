"""The "Sobel" node (paper Listing 2) in Amaranth: a service server filtering each request
image with the per-byte-lane Sobel of spec reconos.md §9.1 into the response."""

from hdl.reconos.threads import SobelServerThread


def build(ctx):
    return SobelServerThread(
        ctx.arch, h_srvs=ctx.handle("filter_server"),
        h_req=ctx.handle("filter_service_msg_req"), h_res=ctx.handle("filter_service_msg_res"),
        image_offsets=ctx.offsets("sensor_msgs/msg/Image"))
