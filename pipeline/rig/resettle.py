"""Held joints that re-settle between sweeps (issue 14: the arm parked, the brake engaging).

Between two sweeps an operator parks the arm to move a fixture; when the brakes
engage, every joint that is held still settles a few encoder counts away from
where it was. Each held joint moves by ``±k`` counts of its ``encoder_resolution``
with ``k`` uniform in ``1..K`` and a random sign, relative to where it held during
the previous sweep (a joint that swept there was commanded back to ``q^s`` first),
and it stays there for the whole sweep: the true joint moves, the encoder reads
the new position. The first sweep starts from the commanded ``q^s``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def resettle(
    q: np.ndarray,
    sweeps: Sequence[int | str],
    resolution: np.ndarray,
    counts: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """Joint positions with the held joints re-settled between sweeps (module docstring).

    Parameters
    ----------
    q : ndarray, shape (K, n)
        Joint positions of the configurations in recording order (deg / cm).
    sweeps : sequence of int or str, length K
        Sweep of each configuration: the 1-based joint that moves, ``"tool"`` (every
        joint held) or ``"check"`` (a validation configuration, left as it is).
    resolution : ndarray, shape (n,)
        One encoder count of each joint (deg / cm).
    counts : int
        ``K``: the largest re-settling, in counts; 0 returns ``q`` unchanged.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (K, n)
    """
    out = np.array(q, float)
    if counts <= 0 or len(out) == 0:
        return out
    n = out.shape[1]
    offset = np.zeros(n)  # counts away from the commanded position, per joint
    moving = -1
    for k, sweep in enumerate(sweeps):
        if sweep == "check":
            continue  # a validation configuration: every joint is commanded, none held
        if k > 0 and sweep != sweeps[k - 1]:
            if moving >= 0:
                offset[moving] = 0.0  # it was commanded back to q^s
            step = rng.integers(1, counts + 1, n) * rng.choice([-1.0, 1.0], n)
            offset += step
        moving = int(sweep) - 1 if sweep != "tool" else -1
        held = np.arange(n) != moving
        out[k, held] += offset[held] * resolution[held]
    return out
