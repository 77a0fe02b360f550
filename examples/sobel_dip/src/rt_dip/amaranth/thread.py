"""The "DIP" node (paper Listing 3) in Amaranth: takes each /image_raw image, has it filtered
by the Sobel service and publishes the result on /image_filtered."""

from hdl.reconos.threads import DipThread


def build(ctx):
    return DipThread(
        ctx.arch, h_sub=ctx.handle("sub"), h_pub=ctx.handle("pub"),
        h_img=ctx.handle("image_msg"), h_srvc=ctx.handle("filter_client"),
        h_req=ctx.handle("filter_service_msg_req"), h_res=ctx.handle("filter_service_msg_res"),
        image_offsets=ctx.offsets("sensor_msgs/msg/Image"))
