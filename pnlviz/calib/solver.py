"""The one non-linear least-squares solver of the refinements (camera and homography alike): a
small Levenberg-Marquardt loop with robust losses by iterative reweighting.

Written here rather than taken from ``scipy.optimize.least_squares`` because the models are
re-linearised at every step (a rotation updated as ``R <- exp([dw]x) R``, a homography as
``M <- M (I + P)``), which a fixed parametrisation cannot express, and because the analytic
Jacobians come with the residuals at no extra cost: each trial step is evaluated with its
Jacobian, which the next iteration uses when the step is accepted.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

LOSSES = ("linear", "huber", "soft_l1", "cauchy")


@dataclass(frozen=True)
class SolverParams:
    loss: str = "linear"  #: linear, huber, soft_l1 or cauchy
    f_scale: float = 2.0  #: where a robust loss bends (the residuals' unit: pixels)
    max_iter: int = 50
    tol: float = 1e-8  #: stop when the cost drops by less than this fraction


def robust_weights(r: np.ndarray, loss: str, c: float) -> np.ndarray:
    """sqrt of the IRLS weight rho'(s) for s = (r / c)^2."""
    if loss == "linear":
        return np.ones_like(r)
    s = (r / c) ** 2
    if loss == "huber":
        return np.sqrt(np.where(s <= 1, 1.0, 1 / np.sqrt(np.maximum(s, 1e-30))))
    if loss == "soft_l1":
        return (1 + s) ** -0.25
    if loss == "cauchy":
        return (1 + s) ** -0.5
    raise ValueError(f"unknown loss {loss!r}; one of {LOSSES}")


def robust_cost(r: np.ndarray, loss: str, c: float) -> float:
    """``0.5 sum rho(r^2)`` (``0.5 c^2 sum rho((r / c)^2)`` for the robust losses)."""
    if loss == "linear":
        return 0.5 * float(r @ r)
    s = (r / c) ** 2
    if loss == "huber":
        rho = np.where(s <= 1, s, 2 * np.sqrt(s) - 1)
    elif loss == "soft_l1":
        rho = 2 * (np.sqrt(1 + s) - 1)
    elif loss == "cauchy":
        rho = np.log1p(s)
    else:
        raise ValueError(f"unknown loss {loss!r}; one of {LOSSES}")
    return 0.5 * c**2 * float(np.sum(rho))


Evaluate = Callable[[Any, bool], tuple[np.ndarray, np.ndarray | None]]


def levenberg_marquardt(evaluate: Evaluate, retract: Callable[[Any, np.ndarray], Any], x0: Any,
                        params: SolverParams = SolverParams()) -> tuple[Any, dict]:
    """Minimise the robust cost of ``evaluate(x, jac) -> (r (n,), J (n, p) or None)``.

    ``retract(x, delta)`` is the model after a step ``delta`` (p,) from ``x``. Returns the final
    model and ``{"success", "cost", "iterations"}``. Damping: ``lam`` starts at 1e-3, times 4 on a
    rejected step (times 10 on a singular system), divided by 3 after an accepted one; it stops
    when the cost drops by less than ``tol`` relatively, or no descent is left (``lam > 1e12``).
    """
    p = params
    x = x0
    r, J = evaluate(x, True)
    cost = robust_cost(r, p.loss, p.f_scale)
    lam, it, success = 1e-3, 0, False
    for it in range(1, p.max_iter + 1):
        if p.loss == "linear":
            Jw, rw = J, r
        else:
            w = robust_weights(r, p.loss, p.f_scale)
            Jw, rw = J * w[:, None], r * w
        A, g = Jw.T @ Jw, Jw.T @ rw
        d = np.maximum(A.diagonal(), 1e-9)  # Marquardt's scaling of the damping
        while True:
            damped = A.copy()
            damped.flat[::len(d) + 1] += lam * d
            try:
                delta = -np.linalg.solve(damped, g)
            except np.linalg.LinAlgError:
                lam *= 10
                if lam > 1e12:
                    break
                continue
            x2 = retract(x, delta)
            with np.errstate(all="ignore"):  # a wild trial step is simply rejected below
                r2, J2 = evaluate(x2, True)
                cost2 = robust_cost(r2, p.loss, p.f_scale)
            if np.isfinite(cost2) and cost2 <= cost:
                break
            lam *= 4
            if lam > 1e12:
                break
        if lam > 1e12:
            success = True  # no descent direction left: at a minimum
            break
        rel = (cost - cost2) / max(cost, 1e-30)
        x, r, J, cost = x2, r2, J2, cost2
        lam = max(lam / 3, 1e-12)
        if rel < p.tol or np.linalg.norm(delta) < 1e-12:
            success = True
            break
    return x, {"success": success, "cost": cost, "iterations": it}
