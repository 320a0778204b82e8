import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


def random_rigid(rng: np.random.Generator, n: int, scale: float = 50.0) -> np.ndarray:
    """n random rigid transforms: uniform rotations, Gaussian translations (cm)."""
    Q, R = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    Q = Q * np.sign(np.diagonal(R, axis1=-2, axis2=-1))[:, None, :]
    Q[np.linalg.det(Q) < 0, :, 0] *= -1
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Q
    T[:, :3, 3] = rng.normal(scale=scale, size=(n, 3))
    return T
