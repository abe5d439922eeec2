"""The rig's physical description, read by every back-end and by ``ffexp``: not a back-end.

- :mod:`~drivers.description.scene`: the scene file (``data/scenes/*.toml``): the arm's
  mount and start pose, the tool and F/T sensor, the target with its funnel and hose, the
  bed, the contact, the KRC's controller limits and FRI timing (:class:`Scene`,
  :func:`load_scene`);
- :mod:`~drivers.description.arm` and one module per arm model
  (:mod:`~drivers.description.lwr4`, :mod:`~drivers.description.ur5e`): an arm's
  kinematics, limits and inertias (:class:`ArmDescription`);
- :mod:`~drivers.description.funnel` and :mod:`~drivers.description.layout`: the funnels'
  geometry (tool length, seat depth) and where a scene puts the bed and the target.

Pure data and maths: no I/O beyond reading a scene file, no MuJoCo, no sockets.
"""

from drivers.description.arm import ArmDescription
from drivers.description.fr3 import FR3
from drivers.description.funnel import seat_depth, tool_tip_offset
from drivers.description.layout import Layout, compute_layout
from drivers.description.lwr4 import LWR4
from drivers.description.scene import Scene, load_scene
from drivers.description.ur5e import UR5E

__all__ = ["FR3", "LWR4", "UR5E", "ArmDescription", "Layout", "Scene", "compute_layout",
           "load_scene", "seat_depth", "tool_tip_offset"]
