"""The speed bound's sampling rule, shared by the compiled peaks of a quintic join
(:mod:`safepath.model._joinkernel`) and the numpy ones of the other joins
(:mod:`safepath.model.interpolation`)."""

from __future__ import annotations

__all__ = ["SAMPLE_SLACK"]

#: Share of a sample spacing by which an interval may be longer than a whole number of
#: them and keep that number of speed samples (``_joinkernel._speed_samples``, and
#: ``interpolation.interval_peaks``): the same points at times rounded to whole nanoseconds (a
#: goal's) and as floats (1e-16 s off) are then sampled alike (one sample more moved the
#: bound by ~1e-6 of a limit, across 1.0 for a replacement the monitor had checked on its
#: float times); a spacing that much longer than ``1 / rate`` is still bounded, the bound
#: adding ``|jerk| dt^2 / 8`` for the spacing ``dt`` it has.
SAMPLE_SLACK = 1e-9
