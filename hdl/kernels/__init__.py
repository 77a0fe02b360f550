"""Streaming compute kernels for hardware nodes (spec kernels.md, reconos.md §9)."""

from .colour import BgrToGray, BgrToHsv, InRange, PixelKernel, TrafficLightDetector
from .gaussian import GaussianBlur
from .image import FrameGuard
from .sobel import Sobel, SobelByteLanes
from .sort import MergeSorter
from .window import WindowFilter

__all__ = ["BgrToGray", "BgrToHsv", "InRange", "PixelKernel", "TrafficLightDetector", "FrameGuard", "GaussianBlur", "MergeSorter", "Sobel", "SobelByteLanes",
           "WindowFilter"]
