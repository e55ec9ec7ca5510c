"""``safepath view``: review and fix a cell's motions in the browser.

This module is imported to register ``view`` (when that command runs, and for the
command list of ``safepath --help``); it stays light (viser loads only when the command
runs).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

__all__ = ["register", "cmd_view", "TOKEN_ENV"]

#: Environment variable that gives the edit token (like ``--token``).
TOKEN_ENV = "SAFEPATH_VIEW_TOKEN"


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
                   help="address to listen on (default: 127.0.0.1, this machine only); "
                        "beyond loopback, pages are read-only until unlocked with the token")
    p.add_argument("--port", type=_port, default=8080,
                   help="port (default: 8080; if taken, the next free one is used)")
    p.add_argument("--strict-port", action="store_true",
                   help="fail instead of moving on when the port is taken")
    p.add_argument("--plans", default=None,
                   help="review trajectories written by `safepath plan` (folder or .json) "
                        "instead of planning at start-up")
    p.add_argument("--seed", type=int, default=0, help="planner seed")
    p.add_argument("--token", default=None,
                   help=f"token that unlocks editing (default: ${TOKEN_ENV}, else a random "
                        "one printed at start when --host is not loopback)")
    p.add_argument("--allow-anonymous-edit", action="store_true",
                   help="let every page edit and save poses.yaml without a token "
                        "(trusted lab network only)")
    p.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    """Serve the review session until Ctrl-C."""
    from ._ports import is_loopback
    from .session import ReviewSession, ViewOptions

    token = args.token
    if token is None and not args.allow_anonymous_edit:
        token = os.environ.get(TOKEN_ENV) or None
    options = ViewOptions(host=args.host, port=args.port, strict_port=args.strict_port,
                          seed=args.seed, token=token,
                          allow_anonymous_edit=args.allow_anonymous_edit)
    session = ReviewSession(args.scene, plans=args.plans, options=options)
    session.start()
    try:
        if session.port_changed:
            print(f"port {args.port} is in use; using port {session.port} instead")
        where = f"{args.host}:{session.port}"
        if args.allow_anonymous_edit and not is_loopback(args.host):
            print(f"WARNING: --allow-anonymous-edit: anyone who can reach {where} can change "
                  f"and save {session.cell.poses_path}, the file the robot's motions are "
                  "planned from (no token; saves are logged in poses.log)", file=sys.stderr)
        elif not is_loopback(args.host):
            print(f"warning: serving on {where}: anyone who can reach it can watch the cell "
                  "and its motions; editing and saving poses need the token (plain HTTP, no "
                  "TLS: on untrusted networks use an SSH tunnel or a reverse proxy)",
                  file=sys.stderr)
        if session.token is not None:
            given = "" if token is None else " (as given)"
            print(f"edit token{given}: {session.token if token is None else '*' * 8}")
        source = f"plans from {args.plans}" if args.plans else "planning in the background"
        print(f"safepath view: {session.cell.scene.name} ({source}) at {session.url}")
        print("press Ctrl-C to stop")
        sys.stdout.flush()
        sys.stderr.flush()
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        print("stopped")
        return 0
    finally:
        session.stop()
