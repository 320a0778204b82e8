"""Stage ``refine`` of a sonic session: :mod:`pipeline.stages.refine` with the raw slant
ranges as an input too (level ``ranges``, the sonic default: the sensor's own parameters
in the fit, :mod:`pipeline.sensor.range_model`)."""

from __future__ import annotations

import dataclasses

from pipeline.stages import refine

STAGE = dataclasses.replace(refine.STAGE, inputs=(*refine.STAGE.inputs, "ranges"))
