"""The monitor's separation kernels against a brute-force numpy pass."""

from __future__ import annotations

import numpy as np
import pytest

from safepath.monitor import _kernels
from safepath.monitor.separation import first_safe


def _robot(rng: np.random.Generator, states: int) -> tuple[np.ndarray, ...]:
    """Six spheres in two bodies moving along a line, one disabled (negative radius),
    with each body's bounding sphere per state."""
    body_start = np.array([0, 3, 6])
    R = rng.uniform(0.02, 0.08, 6)
    R[4] = -1.0
    offsets = rng.uniform(-0.1, 0.1, (6, 3))
    path = np.linspace([0.0, 0.0, 0.0], [0.8, 0.4, 0.2], states)
    C = np.ascontiguousarray(path[:, None, :] + offsets[None])
    Bd = np.empty((states, 2, 4))
    for m in range(2):
        own = [k for k in range(body_start[m], body_start[m + 1]) if R[k] >= 0.0]
        centre = C[:, own].mean(axis=1)
        reach = np.linalg.norm(C[:, own] - centre[:, None], axis=2) + R[own]
        Bd[:, m, :3] = centre
        Bd[:, m, 3] = reach.max(axis=1) * 1.001
    return C, R, body_start, Bd


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_prefix_separation_is_the_running_minimum_of_every_sphere_pair(seed: int) -> None:
    """bucket then prefix_separation give, per state, the running minimum over states of
    |p - c| - r_p - r_s over every element and enabled robot sphere (capped), and the
    element that gives it: the pruning by cell and block spheres drops no closer pair."""
    rng = np.random.default_rng(seed)
    states, cap = 25, 0.6
    C, R, body_start, Bd = _robot(rng, states)
    # A cloud the path runs toward: the bound falls below the cap half way.
    centre = np.array([1.3, 0.65, 0.3])
    E = np.column_stack([centre + rng.uniform(-0.3, 0.3, (200, 3)),
                         rng.uniform(0.0, 0.03, 200)])
    S, cells, cstart, blocks, bstart = _kernels.bucket(np.ascontiguousarray(E), 0.1)
    assert sorted(map(tuple, S)) == sorted(map(tuple, E))
    out = np.full(states, cap)
    arg = np.full(states, -1, dtype=np.int64)
    _kernels.prefix_separation(C, R, body_start, Bd, 0, states, S, cells, cstart, blocks,
                               bstart, cap, out, arg)

    enabled = R >= 0.0
    d = S[None, None, :, :3] - C[:, enabled, None, :]
    gaps = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2])
    gaps = gaps - R[enabled][None, :, None] - S[None, None, :, 3]
    per_state = gaps.min(axis=(1, 2))
    expected = np.minimum.accumulate(np.minimum(per_state, cap))
    assert per_state.min() < cap < per_state.max()  # the cap matters in this case
    np.testing.assert_allclose(out, expected, rtol=0.0, atol=1e-12)
    for s in range(states):
        if expected[s] < cap:
            assert gaps[: s + 1, :, arg[s]].min() == pytest.approx(expected[s], abs=1e-12)
        else:
            assert arg[s] == -1


def test_bucket_spheres_hold_their_contents() -> None:
    """Every element lies inside its cell's sphere, every cell sphere inside its block's."""
    rng = np.random.default_rng(3)
    E = np.column_stack([rng.uniform(-1.0, 1.0, (300, 3)), rng.uniform(0.0, 0.05, 300)])
    S, cells, cstart, blocks, bstart = _kernels.bucket(E, 0.2)
    for c in range(cells.shape[0]):
        inside = S[cstart[c]:cstart[c + 1]]
        reach = np.linalg.norm(inside[:, :3] - cells[c, :3], axis=1) + inside[:, 3]
        assert (reach <= cells[c, 3]).all()
    for k in range(blocks.shape[0]):
        inside = cells[bstart[k]:bstart[k + 1]]
        reach = np.linalg.norm(inside[:, :3] - blocks[k, :3], axis=1) + inside[:, 3]
        assert (reach <= blocks[k, 3]).all()
    assert cstart[-1] == len(E) and bstart[-1] == cells.shape[0]


def test_the_scale_search_returns_only_tested_safe_scales_full_speed_first() -> None:
    """The speed-scale search (fastest first) returns an index its own test passed, or
    none; full speed when it is safe, however the slower scales test (safety need not be
    monotone in the scale: a faster motion rests farther along a path whose clearance
    varies); and the first safe index, in few tests, where safety is monotone."""
    rng = np.random.default_rng(4)
    for _ in range(2000):
        count = int(rng.integers(0, 20))
        verdicts = rng.random(count) < rng.random()
        asked: list[int] = []

        def safe(i: int, verdicts: np.ndarray = verdicts, asked: list[int] = asked) -> bool:
            asked.append(i)
            return bool(verdicts[i])

        got = first_safe(count, safe)
        assert got == count or (got in asked and verdicts[got])
        if count and verdicts[0]:
            assert got == 0 and asked == [0]
        first = int(np.argmax(verdicts)) if verdicts.any() else count
        if np.all(verdicts[first:]):  # unsafe faster than ``first``, safe from it on
            assert got == first and len(asked) <= 2 + int(np.log2(max(count, 1)))
