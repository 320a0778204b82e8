"""The sonic sensor's self-calibration, summarised from a fit of its range block.

Given the block's parameters and their covariance (the block's rows and columns of
the refinement's covariance), :func:`sensor_calibration` states what the verdict
reports: each microphone's range bias and displacement from its recorded position,
each with its σ, and the fitted speed of sound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from pipeline.errors import ArmsigError
from pipeline.sensor.geometry import MICROPHONES
from pipeline.sensor.range_model import RangeBlock

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class SensorCalibration:
    """Fitted sensor parameters with their standard deviations.

    Attributes
    ----------
    bias_cm, bias_sigma_cm : ndarray, shape (4,)
        Range bias of microphones A-D.
    displacement_cm, displacement_sigma_cm : ndarray, shape (4, 3)
        Fitted minus recorded microphone position, sensor frame (C's is 0 by the gauge).
    gradient_per_cm, gradient_sigma_per_cm : float
        ``g``, the speed ratio's change per cm of height.
    knot_t_s, speed_ratio, speed_ratio_sigma : ndarray, shape (n_coef,)
        ``a(t)``'s coefficients (speed ratio to ``S*`` at ``h_ref``) and the times
        where their basis functions peak.
    """

    bias_cm: Array
    bias_sigma_cm: Array
    displacement_cm: Array
    displacement_sigma_cm: Array
    gradient_per_cm: float
    gradient_sigma_per_cm: float
    knot_t_s: Array
    speed_ratio: Array
    speed_ratio_sigma: Array

    def microphone_table(self) -> pa.Table:
        """One row per microphone: bias and displacement with their σ (cm)."""
        cols: dict[str, object] = {
            "microphone": list(MICROPHONES),
            "bias_cm": self.bias_cm,
            "bias_sigma_cm": self.bias_sigma_cm,
        }
        for k, c in enumerate("xyz"):
            cols[f"d{c}_cm"] = self.displacement_cm[:, k]
            cols[f"d{c}_sigma_cm"] = self.displacement_sigma_cm[:, k]
        return pa.table(cols)


def sensor_calibration(
    block: RangeBlock, x: npt.ArrayLike, cov: npt.ArrayLike
) -> SensorCalibration:
    """Summary of the fitted sensor from parameters ``x`` (n,) and covariance ``cov`` (n, n).

    Raises
    ------
    ArmsigError
        ``x`` or ``cov`` do not match the block's parameters.
    """
    xx, cc = np.asarray(x, float), np.asarray(cov, float)
    n = block.n_params
    if xx.shape != (n,) or cc.shape != (n, n):
        raise ArmsigError(
            "the sensor calibration needs the range block's parameters and their covariance",
            expected=f"x ({n},) and cov ({n}, {n}) in param_names order",
            got=f"x {xx.shape}, cov {cc.shape}",
            fix="pass the block's slice of the refinement's parameters and covariance",
        )
    sl = block.slices
    sd = np.sqrt(np.clip(np.diag(cc), 0.0, None))
    jm = block.d_mic_d_geo  # (4, 3, N_GEO), ∂mic/∂x_geo
    c_geo = cc[sl["mic"], sl["mic"]]
    cov_mic = np.einsum("mij,jk,mlk->mil", jm, c_geo, jm)  # (4, 3, 3)
    return SensorCalibration(
        bias_cm=xx[sl["bias"]],
        bias_sigma_cm=sd[sl["bias"]],
        displacement_cm=block.microphones(xx) - block.microphones(block.x_prior),
        displacement_sigma_cm=np.sqrt(np.clip(np.diagonal(cov_mic, axis1=1, axis2=2), 0.0, None)),
        gradient_per_cm=float(xx[sl["gradient"]][0]),
        gradient_sigma_per_cm=float(sd[sl["gradient"]][0]),
        knot_t_s=block.spline.centres_s,
        speed_ratio=xx[sl["speed"]],
        speed_ratio_sigma=sd[sl["speed"]],
    )
