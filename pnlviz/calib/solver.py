"""The one non-linear least-squares solver of the refinements (camera and homography alike): a
small Levenberg-Marquardt loop with robust losses by iterative reweighting.

Written here rather than taken from ``scipy.optimize.least_squares`` because the models are
re-linearised at every step (a rotation updated as ``R <- exp([dw]x) R``, a homography as
``M <- M (I + P)``), which a fixed parametrisation cannot express, and because the analytic
Jacobians come with the residuals at no extra cost: each trial step is evaluated with its
Jacobian, which the next iteration uses when the step is accepted. The clip's model (one camera
per shot, :mod:`pnlviz.calib.shot`) has no analytic Jacobian: it gives its own by finite
differences, asked for only at accepted steps, as a sparse matrix.

A caller that may no longer want an answer (the app's preview of a dragged point, once the point
was let go elsewhere) runs the work inside :func:`cancellable`: every solve checks there before each
iteration and raises :class:`Cancelled` when told to stop.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

LOSSES = ("linear", "huber", "soft_l1", "cauchy")

#: the check of the innermost :func:`cancellable` scope of this thread (None: nothing can stop it)
_stop_check: ContextVar[Callable[[], bool] | None] = ContextVar("pnlviz_stop_check", default=None)


class Cancelled(BaseException):
    """The work was given up (:func:`cancellable`'s check said so). A ``BaseException``, as
    ``KeyboardInterrupt`` is, so that code which turns any ``Exception`` into a failure (a frame's
    "internal error") lets it through to the caller who asked for it."""


@contextlib.contextmanager
def cancellable(should_stop: Callable[[], bool]) -> Iterator[None]:
    """Within it, every solve of this thread asks ``should_stop()`` before each iteration and
    raises :class:`Cancelled` when it says yes (an iteration of a frame's solve is well under a
    millisecond). Scopes nest; outside them nothing is asked."""
    token = _stop_check.set(should_stop)
    try:
        yield
    finally:
        _stop_check.reset(token)


def _check_stop() -> None:
    should_stop = _stop_check.get()
    if should_stop is not None and should_stop():
        raise Cancelled


@dataclass(frozen=True)
class SolverParams:
    loss: str = "linear"  #: linear, huber, soft_l1 or cauchy
    #: where a robust loss bends (the residuals' unit: pixels); one per residual, np.inf where the
    #: residual is squared as it is (a pin of a shot, which bounds its own loss)
    f_scale: float | np.ndarray = 2.0
    max_iter: int = 50
    tol: float = 1e-8  #: stop when the cost drops by less than this fraction
    step_tol: float = 1e-12  #: ... or the step is shorter than this
    max_trials: int | None = None  #: stop after this many rejected steps in a row (None: until lam > 1e12)
    #: soft-L1 only: the normal equations take the loss's own curvature along each residual,
    #: ``rho' + 2 s rho''`` (Triggs' correction), instead of the reweighting's ``rho'``, which
    #: overstates it ``1 + s`` times past the bend and shortens the steps there: the same minimum in
    #: fewer iterations when many residuals are past the bend
    exact_curvature: bool = False


def robust_weights(r: np.ndarray, loss: str, c: float | np.ndarray) -> np.ndarray:
    """sqrt of the IRLS weight rho'(s) for s = (r / c)^2 (1 where ``c`` is infinite)."""
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


def robust_cost(r: np.ndarray, loss: str, c: float | np.ndarray) -> float:
    """``0.5 sum rho(r^2)`` (``0.5 c^2 sum rho((r / c)^2)`` for the robust losses; ``0.5 r^2``
    where ``c``, one per residual, is infinite)."""
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
    if np.ndim(c) == 0:
        return 0.5 * float(c) ** 2 * float(np.sum(rho))
    squared = np.isinf(c)
    bend = np.where(squared, 0.0, c)
    return 0.5 * float(np.sum(np.where(squared, r * r, bend * bend * rho)))


Evaluate = Callable[[Any, bool], tuple[np.ndarray, np.ndarray | None]]
#: ``held(x, delta)``: mask of the parameters a step from ``x`` cannot move, or None
Held = Callable[[Any, np.ndarray], np.ndarray | None]


class _Step(NamedTuple):
    """An accepted step: its size, the point it leads to, that point's residuals, Jacobian (None
    until asked for) and cost."""

    delta: np.ndarray
    x: Any
    r: np.ndarray
    J: Any
    cost: float


def levenberg_marquardt(evaluate: Evaluate, retract: Callable[[Any, np.ndarray], Any], x0: Any,
                        params: SolverParams = SolverParams(),
                        jacobian: Callable[[Any, np.ndarray], Any] | None = None,
                        held: Held | None = None) -> tuple[Any, dict]:
    """Minimise the robust cost of ``evaluate(x, jac) -> (r (n,), J (n, p) or None)``.

    ``retract(x, delta)`` is the model after a step ``delta`` (p,) from ``x``. Returns the final
    model and ``{"success", "cost", "iterations"}``. Damping: ``lam`` starts at 1e-3, times 4 on a
    rejected step (times 10 on a singular system), divided by 3 after an accepted one; it stops
    when the cost drops by less than ``tol`` relatively or the step is shorter than ``step_tol``,
    or no descent is left (``lam > 1e12``, or ``max_trials`` steps rejected in a row).

    ``jacobian(x, r) -> J``: when given, trial steps are evaluated without their Jacobian
    (``evaluate(x, False)``) and the Jacobian is asked for once a step is accepted, with the
    residuals at that point (a Jacobian by finite differences costs many evaluations: the clip's
    in :mod:`pnlviz.calib.shot`). ``J`` may be a scipy sparse matrix; the normal matrix is then
    made dense (it has one row and column per parameter).

    ``held(x, delta) -> mask or None``: the parameters a step cannot move (one at a bound that
    ``retract`` clamps, pushed further out); the step is then solved again without them. Else the
    other parameters would move to make up for a change the clamp undoes, the step is rejected,
    and the descent zigzags along the bound (a camera's k1 at its limit took the 20 iterations
    allowed where it now takes a few).
    """
    p = params
    x = x0
    _check_stop()
    r, J = evaluate(x, jacobian is None)
    cost = robust_cost(r, p.loss, p.f_scale)
    lam, it, success = 1e-3, 0, False
    for it in range(1, p.max_iter + 1):
        _check_stop()
        if J is None:  # asked for at accepted steps (with ``jacobian``), or after a likely last one
            J = jacobian(x, r) if jacobian is not None else evaluate(x, True)[1]
            assert J is not None, "evaluate(x, True) gave no Jacobian"
        A, g = _normal_equations(J, r, p)
        step, lam = _descend(evaluate, retract, x, A, g, cost, lam, p, jacobian is None, held)
        if step is None:
            success = True  # no descent direction left: at a minimum
            break
        rel = (cost - step.cost) / max(cost, 1e-30)
        x, r, J, cost = step.x, step.r, step.J, step.cost
        lam = max(lam / 3, 1e-12)
        if rel < p.tol or np.linalg.norm(step.delta) < p.step_tol:
            success = True
            break
    return x, {"success": success, "cost": cost, "iterations": it}


def _normal_equations(J, r: np.ndarray, p: SolverParams) -> tuple[Any, np.ndarray]:
    """``J^T W J`` and ``J^T W r`` with the loss's IRLS weights ``W``; ``J`` a dense array (the
    normal matrix dense) or a scipy sparse matrix (sparse: a shot's is banded, but for its four
    shared columns, and solved as such)."""
    dense = isinstance(J, np.ndarray)
    if p.loss == "linear":
        Jw, rw = J, r
    else:
        w = robust_weights(r, p.loss, p.f_scale)
        rw = r * w
        if p.exact_curvature and p.loss == "soft_l1":
            # w = (1 + s)^-1/4 = sqrt(rho'): the rows weighed w^3 (the curvature (1 + s)^-3/2), their
            # residuals r / w, so that the gradient stays J^T (rho' r)
            rw = r / w
            w = w ** 3
        if dense:
            Jw = J * w[:, None]
        else:
            import scipy.sparse  # only the clip's model gives a sparse Jacobian

            Jw = scipy.sparse.diags(w) @ J
    A, g = Jw.T @ Jw, Jw.T @ rw
    return (A if dense else A.tocsc()), g


def _damped_step(A, g: np.ndarray, damping: np.ndarray) -> np.ndarray | None:
    """``-(A + diag(damping))^-1 g`` (None when singular); ``A`` dense or scipy sparse."""
    if isinstance(A, np.ndarray):
        damped = A.copy()
        damped.flat[::len(damping) + 1] += damping
        try:
            return -np.linalg.solve(damped, g)
        except np.linalg.LinAlgError:
            return None
    import scipy.sparse
    import scipy.sparse.linalg

    with warnings.catch_warnings():
        warnings.simplefilter("error", scipy.sparse.linalg.MatrixRankWarning)
        try:
            delta = scipy.sparse.linalg.spsolve((A + scipy.sparse.diags(damping)).tocsc(), g)
        except (RuntimeError, scipy.sparse.linalg.MatrixRankWarning):
            return None
    return -delta if np.all(np.isfinite(delta)) else None


def _held_step(A: np.ndarray, g: np.ndarray, damping: np.ndarray, fixed: np.ndarray) -> np.ndarray | None:
    """:func:`_damped_step` with the parameters of mask ``fixed`` kept where they are (``A``
    dense)."""
    free = ~fixed
    sub = _damped_step(A[np.ix_(free, free)], g[free], damping[free])
    if sub is None:
        return None
    step = np.zeros(len(g))
    step[free] = sub
    return step


def _likely_last(A: np.ndarray, g: np.ndarray, delta: np.ndarray, cost: float, tol: float) -> bool:
    """Whether the step's predicted drop (the quadratic model's, ``-(g.d + d.A d / 2)``) is under
    the fraction of the cost that stops the solve: its Jacobian would go unused, so the trial is
    evaluated without it, and asked for after all when the solve goes on (WC14, default settings:
    3 of 405 such steps; every solve's last Jacobian saved)."""
    if not isinstance(A, np.ndarray):
        return False
    predicted = -(float(g @ delta) + 0.5 * float(delta @ A @ delta))
    return predicted < tol * cost


def _descend(evaluate: Evaluate, retract, x, A: np.ndarray, g: np.ndarray, cost: float, lam: float,
             p: SolverParams, with_jacobian: bool, held: Held | None = None) -> tuple[_Step | None, float]:
    """Damped steps from ``x``, more damped after each rejection, until one does not raise the
    cost: ``(that step, lam)``, or ``(None, lam)`` when none is left to try."""
    d = np.maximum(A.diagonal(), 1e-9)  # Marquardt's scaling of the damping
    trials = 0
    while lam <= 1e12 and (p.max_trials is None or trials < p.max_trials):
        trials += 1
        delta = _damped_step(A, g, lam * d)
        fixed = None if delta is None or held is None else held(x, delta)
        if fixed is not None:
            delta = _held_step(A, g, lam * d, fixed)
        if delta is None:
            lam *= 10
            continue
        x2 = retract(x, delta)
        with np.errstate(all="ignore"):  # a wild trial step is simply rejected below
            r2, J2 = evaluate(x2, with_jacobian and not _likely_last(A, g, delta, cost, p.tol))
            cost2 = robust_cost(r2, p.loss, p.f_scale)
        if np.isfinite(cost2) and cost2 <= cost:
            return _Step(delta, x2, r2, J2, cost2), lam
        lam *= 4
    return None, lam
