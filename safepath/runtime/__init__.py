"""Planning that never blocks the caller: worker processes answered through futures.

For a ROS 2 node or a browser review session: :class:`RuntimePlanner` keeps the cell
loaded in worker processes and returns a ``concurrent.futures.Future`` for every
request, so the caller's threads keep running while OMPL, Pinocchio and TOPPRA work
(they hold the interpreter lock, which would stall every thread of the caller).

Example::

    from safepath import runtime

    planner = runtime.RuntimePlanner("scenes/quality_check_cell")
    planner.plan_route("phase1").add_done_callback(on_planned)
"""

from ._transport import WorkerError
from .runtime_planner import RuntimePlanner, RuntimeStats

__all__ = ["RuntimePlanner", "RuntimeStats", "WorkerError"]
