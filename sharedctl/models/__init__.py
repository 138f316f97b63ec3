"""Euler–Lagrange plant models, linear in their parameters θ (paper (1), (11))."""
from .base import EulerLagrangeModel
from .omni_robot import OmniRobot
from .planar_arm import PlanarArm

__all__ = ["EulerLagrangeModel", "OmniRobot", "PlanarArm"]
