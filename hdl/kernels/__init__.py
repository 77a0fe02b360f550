"""Streaming compute kernels for hardware nodes (docs/kernels.md, docs/reconos.md,
docs/kernels.md)."""

from .ball_control import BallControl
from .colour import BgrToGray, BgrToHsv, InRange, PixelKernel, TrafficLightDetector
from .compensation import ImageCompensation
from .equalize import EqualizeHist
from .gaussian import GaussianBlur
from .image import FrameGuard
from .inverse_kinematics import InverseKinematics
from .lane import LaneControl, LaneDetector, LightEvent, LightNode
from .mnist import MnistCnn, MnistMacArray
from .pid import PidController
from .servo_pwm import ServoPwm
from .sobel import Sobel, SobelByteLanes
from .sort import MergeSorter
from .warp import PerspectiveWarp
from .window import WindowFilter

__all__ = ["BallControl", "BgrToGray", "BgrToHsv", "EqualizeHist", "FrameGuard", "GaussianBlur",
           "ImageCompensation", "InRange", "InverseKinematics", "LaneControl", "LaneDetector", "LightEvent", "LightNode", "MergeSorter", "MnistCnn", "MnistMacArray", "PerspectiveWarp", "PidController",
           "PixelKernel", "ServoPwm", "Sobel", "SobelByteLanes", "TrafficLightDetector",
           "WindowFilter"]
