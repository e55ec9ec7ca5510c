"""The bundled cells' application logic, built on the library.

A cell's application is what one cell does with the library's plans: its controller (the
state machine that turns sensor readings into goals), its process model, its run-time
setup. It sits above the library's layers (planning, ros, monitor) and nothing in the
library imports it (an import-linter contract in ``pyproject.toml``). A user's own cell
would have its own such package, outside safepath.

* :mod:`safepath.cells.pouring`: the pouring cell's gravimetric pour (the scale stops the
  tilt).
* :mod:`safepath.cells.quality_check`: the quality-check cell's state machine (a vial
  picked from the conveyor, tested, then packed or rejected).
"""
