"""The chain's compensation node as a ReconOS hardware thread (docs/av_chain.md)."""

from gen.av_chain import reconros_thread


def build(ctx):
    return reconros_thread(ctx, "compensation")
