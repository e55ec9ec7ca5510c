"""Robot descriptions: a robot folder (``robot.yaml`` + URDF) or a bare URDF into a
:class:`~safepath.model.robot.Robot`.

:func:`~.robot_folder.load_robot` reads a bundled or user robot folder, or a URDF
alone (``_bare_urdf``; example-robot-data's robots through ``_erd``); ``_joint_roles``
decides which joints are planned, which are locked and which robots are refused.
"""

from .robot_folder import ROBOTS_DIR, load_robot, robot_names

__all__ = ["ROBOTS_DIR", "load_robot", "robot_names"]
