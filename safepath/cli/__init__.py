"""The ``safepath`` command: ``check``, ``plan``, ``teach``, ``view``, ``sim`` and
``build-kernels`` (:func:`main`; ``plan`` in ``_plan``, ``teach`` in ``_teach``)."""

from ._main import main

__all__ = ["main"]
