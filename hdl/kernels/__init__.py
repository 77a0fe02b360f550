"""Streaming compute kernels for hardware nodes (spec kernels.md, reconos.md §9, finemb.md §6)."""

from .colour import BgrToGray, BgrToHsv, InRange, PixelKernel, TrafficLightDetector
from .equalize import EqualizeHist
from .gaussian import GaussianBlur
from .image import FrameGuard
from .inverse_kinematics import InverseKinematics
from .mnist import MnistCnn
from .pid import PidController
from .sobel import Sobel, SobelByteLanes
from .sort import MergeSorter
from .window import WindowFilter

__all__ = ["BgrToGray", "BgrToHsv", "EqualizeHist", "FrameGuard", "GaussianBlur", "InRange",
           "InverseKinematics", "MergeSorter", "MnistCnn", "PidController", "PixelKernel", "Sobel",
           "SobelByteLanes", "TrafficLightDetector", "WindowFilter"]
