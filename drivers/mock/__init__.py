"""Scripted back-ends for tests: replay measurements, record commands."""

from drivers.mock.driver import MockFtSensor, MockRobot

__all__ = ["MockFtSensor", "MockRobot"]
