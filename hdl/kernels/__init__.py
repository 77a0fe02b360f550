"""Streaming compute kernels for hardware nodes (spec kernels.md, reconos.md §9)."""

from .sobel import SobelByteLanes
from .sort import MergeSorter

__all__ = ["MergeSorter", "SobelByteLanes"]
