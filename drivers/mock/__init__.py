"""Scripted back-ends for tests and dry runs: replay states, record commands."""

from .driver import MockFtSensor, MockRobot, NoisyFtSensor, stationary_robot

__all__ = ["MockFtSensor", "MockRobot", "NoisyFtSensor", "stationary_robot"]
