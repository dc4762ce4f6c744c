"""One result type for every fit (camera, corner, footprint), as optimistix's ``Solution`` and
``RESULTS`` are for its solvers: the solution, its covariance, the residuals at it, the solver's
steps and a status whose message says what to do about it.

The covariance of a least-squares fit whose residuals are already divided by their noise is
``(J^T J)^-1`` at the solution (:func:`covariance`); with the solver working on scaled unknowns
``u = x / scale`` it is ``scale_i scale_j (J_u^T J_u)^-1_ij``.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["FitStatus", "FitResult", "HasFit", "covariance", "fit_result"]

#: J^T J above this condition number counts as singular: the data do not fix every unknown.
MAX_CONDITION = 1e14


class FitStatus(enum.Enum):
    """Why a fit stopped. ``value`` is the short code written to JSON; ``message`` says what to do."""

    CONVERGED = "converged"
    STEP_LIMIT = "step_limit"
    SINGULAR = "singular"
    DIVERGED = "diverged"
    DEGENERATE = "degenerate"

    @property
    def message(self) -> str:
        return _MESSAGES[self]

    @property
    def ok(self) -> bool:
        return self is FitStatus.CONVERGED


_MESSAGES = {
    FitStatus.CONVERGED: "converged: the gradient vanishes at the solution",
    FitStatus.STEP_LIMIT: "did not converge within the step limit; check the inputs (corners, headings, wall "
    "order) or give more prior information (--focal-px, --camera-height)",
    FitStatus.SINGULAR: "too few constraints: the Jacobian is singular, so some unknowns are not determined; give "
    "the missing information (--focal-px and --camera-height, visible mortar joints, a heading "
    "or theta per wall)",
    FitStatus.DIVERGED: "diverged to non-finite values; check the inputs and start from better estimates",
    FitStatus.DEGENERATE: "the solution is degenerate (a length driven to zero or below); the measurements do not "
    "describe a possible structure: check the wall order and their headings or theta values",
}


@dataclass(frozen=True)
class FitResult:
    """A fit's solution ``value`` (unknowns in the order ``names``, SI units, angles in radians),
    its ``covariance``, the ``residuals`` at it (each divided by its noise), the solver's ``steps``
    and its :class:`FitStatus`."""

    value: np.ndarray
    names: tuple[str, ...]
    covariance: np.ndarray
    residuals: np.ndarray
    steps: int
    status: FitStatus

    def __getitem__(self, name: str) -> float:
        return float(self.value[self.names.index(name)])

    def sigma(self, name: str) -> float:
        i = self.names.index(name)
        return float(math.sqrt(max(self.covariance[i, i], 0.0)))

    @property
    def sigmas(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def ok(self) -> bool:
        return self.status.ok

    @property
    def rms_residual(self) -> float:
        r = np.asarray(self.residuals)
        return float(np.sqrt(np.mean(r**2))) if r.size else 0.0

    def to_json(self) -> dict:
        return {
            "status": self.status.value,
            "status_message": self.status.message,
            "solver_steps": self.steps,
            "covariance": {"order": list(self.names), "matrix": self.covariance.tolist()},
        }


class HasFit:
    """What a domain result that holds a ``fit`` (:class:`FitResult`) passes through from it."""

    fit: FitResult

    @property
    def params(self) -> np.ndarray:
        return self.fit.value

    @property
    def covariance(self) -> np.ndarray:
        return self.fit.covariance

    @property
    def status(self) -> FitStatus:
        return self.fit.status

    @property
    def steps(self) -> int:
        return self.fit.steps


def covariance(jac: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray | None:
    """``(J^T J)^-1`` of the residual Jacobian ``jac`` ``(m, n)`` at the solution, in the units of the
    unknowns ``x = u * scale``; None when ``J^T J`` is singular (condition above :data:`MAX_CONDITION`)."""
    jac = np.asarray(jac, dtype=np.float64)
    jtj = jac.T @ jac
    if not np.all(np.isfinite(jtj)):
        return None
    # one symmetric eigen-decomposition gives both the condition number and the inverse: numpy's
    # LU inverse of this 11 x 11 matrix waited 6-14 ms on OpenBLAS's threads whenever the other
    # core was busy (a rectify's background work), against 0.02 ms for the eigen-decomposition
    try:
        w, v = np.linalg.eigh(jtj)
    except np.linalg.LinAlgError:
        return None
    if w[0] <= 0.0 or w[-1] > MAX_CONDITION * w[0]:
        return None
    cov = (v / w) @ v.T
    if not np.all(np.isfinite(cov)):
        return None
    if scale is not None:
        s = np.asarray(scale, dtype=np.float64)
        cov = cov * np.outer(s, s)
    return cov


def fit_result(u, converged, steps, jac, residuals, names, scale=None) -> FitResult:
    """The :class:`FitResult` of a solver's output: scaled unknowns ``u``, its convergence flag and
    step count, the Jacobian and the residuals at ``u``. Non-finite values are DIVERGED, a
    singular Jacobian SINGULAR (covariance NaN), an unconverged solve STEP_LIMIT."""
    u = np.asarray(u, dtype=np.float64)
    value = u * (1.0 if scale is None else np.asarray(scale, dtype=np.float64))
    n = len(value)
    nan = np.full((n, n), np.nan)
    if not np.all(np.isfinite(value)):
        return FitResult(value, tuple(names), nan, np.asarray(residuals), int(steps), FitStatus.DIVERGED)
    cov = covariance(jac, scale)
    if cov is None:
        return FitResult(value, tuple(names), nan, np.asarray(residuals), int(steps), FitStatus.SINGULAR)
    status = FitStatus.CONVERGED if bool(converged) else FitStatus.STEP_LIMIT
    return FitResult(value, tuple(names), cov, np.asarray(residuals, dtype=np.float64), int(steps), status)
