"""Synthetic target positions for the feature-identification tests."""

import numpy as np


def random_unit(rng: np.random.Generator, shape: tuple[int, ...] = ()) -> np.ndarray:
    v = rng.normal(size=(*shape, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def arc(
    rng: np.random.Generator,
    n: int,
    sweep_deg: float,
    radius: float,
    *,
    normal: np.ndarray | None = None,
    center: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n noiseless points, equally spaced joint readings, positive rotation about ``normal``.

    Returns (points (n, 3), normal (3,), center (3,)); cm.
    """
    a = random_unit(rng) if normal is None else np.asarray(normal, float)
    c = rng.normal(scale=60.0, size=3) if center is None else np.asarray(center, float)
    u = np.cross(a, random_unit(rng))
    u /= np.linalg.norm(u)
    v = np.cross(a, u)  # (u, v, a) right-handed: increasing angle = positive about a
    th = rng.uniform(-np.pi, np.pi) + np.radians(np.linspace(0.0, sweep_deg, n))
    pts = c + radius * (np.cos(th)[:, None] * u + np.sin(th)[:, None] * v)
    return pts, a, c


def cross_angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angle between unit vectors (rad), accurate near 0 (arccos is not)."""
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.sum(u * v, axis=-1))
