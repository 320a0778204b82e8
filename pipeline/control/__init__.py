"""The control wing: driving a robot with its signature (Chapter 5).

- :mod:`~pipeline.control.controller`: targets solved with the identified model (the
  generic solvers of :mod:`pipeline.kinematics.ik`);
- :mod:`~pipeline.control.puma560_inverse`: the Puma's closed-form design inverse, the
  start of Newton-Raphson and the ``F_d⁻¹`` of the Jacobi method;
- :mod:`~pipeline.control.puma560_solver`: the real-time Puma solver, one compiled call
  per target, its kernels in :mod:`~pipeline.control.puma560_start` (the design start),
  :mod:`~pipeline.control.puma560_newton` and :mod:`~pipeline.control.puma560_jacobi`;
- :mod:`~pipeline.control.convergence`: how the solvers converge (the thesis's tables).
"""
