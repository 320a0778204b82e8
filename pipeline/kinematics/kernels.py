"""armsig's numba kernels, made on first use: :class:`Kernel`, and :func:`interpreted`,
which runs them as Python for a process that solves one target and exits.

Why lazy: loading the compiled kernels costs a process ~0.5 s of CPU before the first
answer (issue 45: importing numba 0.15-0.25 s; numba's first cached load installs its
implementation registries, ~0.3 s, which import scipy.linalg to look for a BLAS), where
the kernel's own work on one target is ~5 µs. A module that defines kernels imports no
numba; numba comes in with the first compiled call (or :attr:`Kernel.dispatcher`).

Why interpreted: the README's ``pipeline ik --pose`` solves one target. Run as Python
(the same source, :attr:`Kernel.py_func`, ~1.5 ms a target) it answers with the same
arithmetic: IEEE double operations in the order written, and the libm functions the
machine code calls (``math.cos``, ``math.atan2``, ...; numpy's scalar ``arctan2`` rounds
differently). Where Python refuses what the machine code computes through (a domain or
zero-division error, a NaN or an overflow: only off the normal path), the call runs again
compiled, so the answer is always the compiled kernels' or the same arithmetic's.
"""

from __future__ import annotations

import functools
import math
import threading
import types
from collections.abc import Callable
from typing import Any

import numpy as np

#: Every kernel made in this process (:func:`interpreted` switches them all).
_KERNELS: list[Kernel] = []
#: Held while a kernel's dispatcher is made (numba imported, the cache found).
_MAKING = threading.RLock()
#: Whether :func:`interpreted` is running (kernels made meanwhile start as Python).
_INTERPRETING = False


class Kernel:
    """A numba kernel of ``py_func`` (``numba.njit(**options)``, cached on disk by
    :func:`pipeline.kinematics.kernel_cache.njit_cached`), compiled or loaded on first use.

    Calling it runs :attr:`run`: the numba dispatcher, or the Python twin inside
    :func:`interpreted`. Callers on a real-time path call ``kernel.run(...)`` (no Python
    frame of this class in between). numba types a kernel that another kernel calls as
    its dispatcher (:func:`_register_numba_type`); other attributes (``signatures``,
    ``stats``, ...) are the dispatcher's."""

    def __init__(self, func: Callable[..., Any], options: dict[str, Any]) -> None:
        functools.update_wrapper(self, func)
        self.py_func = func
        self._options = options
        _KERNELS.append(self)
        if _INTERPRETING:  # a module of kernels imported inside interpreted()
            self.__dict__["run"] = self._twin_on_first_call

    def _twin_on_first_call(self, *args: Any) -> Any:
        # Made at the first call, when the module (the twin's globals) is complete.
        twin = self.__dict__["run"] = self.twin()
        return twin(*args)

    def __call__(self, *args: Any) -> Any:
        return self.run(*args)

    def __getattr__(self, name: str) -> Any:
        # Only for attributes not set yet: the dispatcher and `run` made here, once.
        if name.startswith("__"):
            raise AttributeError(name)
        if name in ("dispatcher", "run"):
            made = self.__dict__
            with _MAKING:  # a batch's threads may call a kernel first at once
                if "dispatcher" not in made:
                    from pipeline.kinematics.kernel_cache import njit_cached

                    _register_numba_type()
                    made["dispatcher"] = njit_cached(self.py_func, **self._options)
                made.setdefault("run", made["dispatcher"])
            return made[name]
        return getattr(self.dispatcher, name)

    def twin(self) -> Callable[..., Any]:
        """``py_func`` with the scalar math of the machine code (:data:`_SCALAR_NP`)."""
        f = self.py_func
        env = dict(f.__globals__, np=_SCALAR_NP)
        return types.FunctionType(f.__code__, env, f.__name__, f.__defaults__, f.__closure__)


@functools.cache
def _register_numba_type() -> None:
    """numba types a :class:`Kernel` global as its dispatcher (a call from a kernel)."""
    from numba.core import types as nt
    from numba.extending import typeof_impl

    @typeof_impl.register(Kernel)
    def _typeof_kernel(val: Kernel, c: Any) -> Any:
        return nt.Dispatcher(val.dispatcher)


class _ScalarNumpy:
    """``numpy`` for a kernel run as Python: the scalar functions the kernels call on
    floats are libm's, as in the machine code; every other name is numpy's."""

    cos, sin, sqrt, hypot = math.cos, math.sin, math.sqrt, math.hypot
    arctan2, isfinite = math.atan2, math.isfinite

    def __getattr__(self, name: str) -> Any:
        return getattr(np, name)


_SCALAR_NP = _ScalarNumpy()


def interpreted(fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)`` with every kernel run as Python (module docstring), or, where
    Python raises an arithmetic error the machine code does not, again compiled. For a
    process that solves a few targets and exits (``ik --pose``); not thread-safe."""
    global _INTERPRETING
    saved = {id(k): k.__dict__.get("run") for k in _KERNELS}
    for k in _KERNELS:
        k.__dict__["run"] = k.twin()
    _INTERPRETING = True
    try:
        with np.errstate(divide="raise", over="raise", invalid="raise"):
            return fn(*args, **kwargs)
    except (ArithmeticError, ValueError):
        pass  # run compiled, below
    finally:
        _INTERPRETING = False
        for k in _KERNELS:
            run = saved.get(id(k))
            if run is None:
                del k.__dict__["run"]
            else:
                k.__dict__["run"] = run
    return fn(*args, **kwargs)
