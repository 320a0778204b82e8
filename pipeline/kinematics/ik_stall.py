"""The stall test shared by the numpy iterations (:mod:`.ik`) and the compiled
Newton-Raphson (:mod:`.ik_compiled`): one constant, so the two cannot disagree."""

from __future__ import annotations

#: A target whose step is below one encoder count and whose scaled residual fell
#: by less than 10 % in that step has stalled. A reachable target shrinks its
#: residual by orders of magnitude per step once the steps are that small (even
#: Jacobi's linear rate is ~1e-2 per iteration for realistic signatures), so
#: 0.9 only catches minima of the residual.
STALL_RATIO = 0.9
