"""One Levenberg-Marquardt call shared by the calibration fits (optimistix, inside ``jax.jit``)."""

from __future__ import annotations

from .._jax import jax, jnp

__all__ = ["least_squares"]


def least_squares(residual_fn, y0, args, *, max_steps: int = 200, tol: float = 1e-10):
    """Solve ``min |residual_fn(y, args)|^2``; returns ``(y, converged, steps, jacobian, residuals)``
    (hand them to :func:`~calib_masonry.calibrate.fitresult.fit_result` outside ``jax.jit``).

    optimistix's LM can keep rejecting steps at a minimum where the cost no longer changes in
    float64, and then reports the step limit. First-order optimality, a gradient ``J^T r`` that
    vanishes relative to the column norms of ``J`` times ``|r|``, is the honest test of having
    converged, so either counts.
    """
    import optimistix as optx

    sol = optx.least_squares(
        residual_fn, optx.LevenbergMarquardt(rtol=tol, atol=tol), y0, args=args, max_steps=max_steps, throw=False
    )
    y = sol.value
    jac = jax.jacfwd(residual_fn)(y, args)
    r = residual_fn(y, args)
    curv = jnp.sqrt(jnp.sum(jac**2, axis=0)) * (jnp.sqrt(r @ r) + 1.0)
    stationary = jnp.all(jnp.abs(jac.T @ r) <= 1e-6 * curv)
    return y, (sol.result == optx.RESULTS.successful) | stationary, sol.stats["num_steps"], jac, r
