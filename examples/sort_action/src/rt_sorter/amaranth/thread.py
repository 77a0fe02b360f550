"""The sort action server node: accepts a goal of 1..block_size values, sends the merge
passes done as feedback (percent, ending with 100), then the sorted values as its result."""

from hdl.reconos.threads import SortActionThread


def build(ctx):
    return SortActionThread(
        ctx.arch, h_as=ctx.handle("server"), h_goal=ctx.handle("sort_msg_goal_req"),
        h_res=ctx.handle("sort_msg_result_res"), h_fb=ctx.handle("sort_msg_feedback"),
        goal_offset=ctx.offsets("sorter_msgs/action/Sort_SendGoal_Request")["goal"],
        res_offset=ctx.offsets("sorter_msgs/action/Sort_GetResult_Response")["result"],
        fb_offset=ctx.offsets("sorter_msgs/action/Sort_FeedbackMessage")["feedback"],
        block_size=ctx.param("block_size", 2048, int))
