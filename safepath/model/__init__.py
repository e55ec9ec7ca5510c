"""The model: the robot, its tool, the scene, the controller and the trajectory.

What every layer above reads and none redefines: :class:`~.robot.Robot` (kinematics,
limits, collision geometry; with its locked joints, ``_locked``), the tool it carries
(:mod:`.tool`), the scene's objects (:mod:`.scene`), the trajectory controller that
executes goals (:mod:`.controller_spec`, :mod:`.execution`, the join kernel
``_joinkernel``) and the timed :class:`~.trajectory.Trajectory`; the joint table and the
forward-kinematics kernel the planner's kernels share (``_joint_table``, ``_fk_kernel``).

Loading a robot from its folder or a URDF is :mod:`safepath.description`'s.
"""
