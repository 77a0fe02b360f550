"""The chain's lane following node as a ReconOS hardware thread (docs/av_chain.md)."""

from gen.av_chain import reconros_thread


def build(ctx):
    return reconros_thread(ctx, "lane_following")
