"""``safepath view``: review and fix a cell's motions in the browser.

This module is imported by every ``safepath`` command to register ``view``; it stays
light (viser loads only when the command runs).
"""

from __future__ import annotations

import argparse
import sys
import time

__all__ = ["register", "cmd_view"]


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"port must be in [0, 65535], got {value}")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``view`` command."""
    p = sub.add_parser("view", help="review, edit and re-plan a cell's motions in the browser")
    p.add_argument("scene", help="scene folder (e.g. scenes/quality_check_cell)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default: 127.0.0.1, this machine only)")
    p.add_argument("--port", type=_port, default=8080,
                   help="port (default: 8080; if taken, the next free one is used)")
    p.add_argument("--strict-port", action="store_true",
                   help="fail instead of moving on when the port is taken")
    p.add_argument("--plans", default=None,
                   help="review trajectories written by `safepath plan` (folder or .json) "
                        "instead of planning at start-up")
    p.add_argument("--seed", type=int, default=0, help="planner seed")
    p.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    """Serve the review session until Ctrl-C."""
    from .session import ReviewSession, ViewOptions

    options = ViewOptions(host=args.host, port=args.port, strict_port=args.strict_port,
                          seed=args.seed)
    session = ReviewSession(args.scene, plans=args.plans, options=options)
    session.start()
    try:
        if session.port_changed:
            print(f"port {args.port} is in use; using port {session.port} instead")
        source = f"plans from {args.plans}" if args.plans else "planning in the background"
        print(f"safepath view: {session.cell.scene.name} ({source}) at {session.url}")
        print("press Ctrl-C to stop")
        sys.stdout.flush()
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        print("stopped")
        return 0
    finally:
        session.stop()
