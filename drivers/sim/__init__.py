"""MuJoCo world: LWR4+ with its KRC impedance law, air-bed target, funnels, F/T sensor."""

from drivers.sim.driver import SimFtSensor, SimRobot, open_sim
from drivers.sim.scene import Scene, load_scene
from drivers.sim.world import SimWorld

__all__ = ["Scene", "SimFtSensor", "SimRobot", "SimWorld", "load_scene", "open_sim"]
