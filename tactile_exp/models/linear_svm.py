"""The baselines' classifier (`linear_svm`, rows A-F): StandardScaler -> linear SVM, C chosen by
leave-3-objects-out CV.

On a small data set, where no draw of 3 held-out objects keeps both classes in training and
gives both among the held-out objects, fewer objects are held out (2, then 1), with a warning; that
needs at least two objects of each class. With fewer, the middle C of the grid is used, also with
a warning.

The authors (BASELINES.md §1.3) drew 100 random sets of 3 training objects, held out all their
trials, skipped draws whose training part had one class, and scored F1. Gao et al. report AUC, so
here C is scored by ROC AUC of the held-out decision values, pooled over the draws (a single
draw's 3 objects rarely hold both classes).

The SVM is `LinearSVC`'s problem (l2 penalty, squared hinge, balanced class weights, the bias a
regularised feature of 1) solved to its optimum by `SquaredHingeSVM`. liblinear, as `LinearSVC`
runs it (tolerance 1e-4, at most 10,000 iterations), stops short at large C on these nearly
separable features: at C=10 its held-out AUCs were off by up to 0.03 and changed the chosen C
(measured on the synthetic file), and it took thousands of iterations (25x slower).
``solver="liblinear"`` keeps it selectable, as the authors ran it.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import scipy.linalg
from sklearn.base import BaseEstimator
from sklearn.exceptions import ConvergenceWarning
from sklearn.metrics import roc_auc_score
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import LinearSVC
from sklearn.utils.class_weight import compute_sample_weight
from threadpoolctl import threadpool_limits

from tactile_exp import cores
from tactile_exp.data.layout import Instances
from tactile_exp.models.base import EpochCallback, History, Model, clone
from tactile_exp.models.registry import MODELS

# On standardised features C above 10 is near hard-margin and ~10x slower to fit (liblinear).
DEFAULT_CS: tuple[float, ...] = tuple(np.logspace(-4, 1, 6))
AUTHORS_CS: tuple[float, ...] = tuple(np.linspace(1e2, 1e6, 100))  # nearly hard-margin


SOLVERS = ("newton", "liblinear")


class SquaredHingeSVM(BaseEstimator):
    """``LinearSVC(C=C, dual=False, class_weight="balanced")``'s objective, solved exactly:
    min_w 0.5 |w|^2 + sum_i c_i max(0, 1 - s_i w.[x_i, 1])^2, s_i = +-1, c_i = C n / (2 n_class).

    Newton steps on the rows inside the margin with an exact line search (the finite Newton
    method of Keerthi and DeCoste, JMLR 2005): a few (d+1)^2 solves, fine for the baselines'
    <= 204 features. Stops when the gradient is ``tol`` times its starting norm: 1-60 steps for
    C <= 100, ~200 near hard margin (C = 1e6, the authors' grid). Best run under
    ``threadpool_limits(1)``, as `ObjectCVLinearSVM` does: its BLAS calls are small.
    """

    def __init__(self, C: float = 1.0, tol: float = 1e-10, max_iter: int = 1000) -> None:
        self.C = C
        self.tol = tol
        self.max_iter = max_iter

    def fit(self, X: np.ndarray, y: np.ndarray) -> SquaredHingeSVM:
        X = np.asarray(X, dtype=np.float64)
        self.classes_ = np.unique(y)
        if len(self.classes_) != 2:
            raise ValueError(f"SquaredHingeSVM: needs two classes, got {self.classes_.tolist()}")
        positive = np.asarray(y) == self.classes_[1]
        c = self.C * compute_sample_weight("balanced", positive)  # LinearSVC's class weights
        signed = np.hstack([X, np.ones((len(X), 1))]) * np.where(positive, 1.0, -1.0)[:, None]
        w, self.n_iter_ = _finite_newton(signed, c, tol=self.tol, max_iter=self.max_iter)
        self.coef_, self.intercept_ = w[None, :-1], w[-1:]
        self.n_features_in_ = X.shape[1]
        return self

    def decision_function(self, X: np.ndarray) -> np.ndarray:
        """Signed distance to the hyperplane, positive for ``classes_[1]`` (as `LinearSVC`)."""
        return np.asarray(X, dtype=np.float64) @ self.coef_[0] + self.intercept_[0]


def _finite_newton(
    A: np.ndarray, c: np.ndarray, *, tol: float, max_iter: int
) -> tuple[np.ndarray, int]:
    """argmin_w 0.5 |w|^2 + sum_i c_i max(0, 1 - A_i w)^2 and the Newton steps it took."""
    w = np.zeros(A.shape[1])
    for n_iter in range(1, max_iter + 1):
        r = 1.0 - A @ w
        inside = r > 0
        Ai, ci = A[inside], c[inside]
        grad = w - 2.0 * Ai.T @ (ci * r[inside])
        norm = float(np.linalg.norm(grad))
        if n_iter == 1:
            stop = tol * max(norm, 1.0)
        if norm <= stop:
            return w, n_iter - 1
        hessian = (Ai.T * (2.0 * ci)) @ Ai
        hessian.flat[:: len(w) + 1] += 1.0
        step = -scipy.linalg.solve(hessian, grad, assume_a="pos")
        w = w + _line_minimum(w, step, r, A @ step, c) * step
    message = f"SquaredHingeSVM: not converged in {max_iter} Newton steps"
    warnings.warn(message, ConvergenceWarning, stacklevel=3)
    return w, max_iter


def _line_minimum(
    w: np.ndarray, step: np.ndarray, r: np.ndarray, delta: np.ndarray, c: np.ndarray
) -> float:
    """The t minimising the objective along ``w + t step``: the root of its derivative, which
    is piecewise linear and increasing in t (bisection to float precision)."""

    def slope(t: float) -> float:
        rt = r - t * delta
        inside = rt > 0
        return step @ w + t * (step @ step) - 2.0 * np.sum(c[inside] * rt[inside] * delta[inside])

    lo, hi = 0.0, 1.0
    while slope(hi) < 0:  # the full Newton step is usually right; past it, widen
        lo, hi = hi, 2.0 * hi
    while hi - lo > 1e-12 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if slope(mid) < 0 else (lo, mid)
    return hi


class LeavePObjectsOut:
    """Up to ``n_draws`` distinct random draws of ``p`` whole objects held out.

    Draws whose training part has a single class are skipped; objects are never split.
    """

    def __init__(self, p: int = 3, n_draws: int = 20, seed: int = 0) -> None:
        self.p = p
        self.n_draws = n_draws
        self.seed = seed

    def split(
        self, X: np.ndarray, y: np.ndarray, groups: np.ndarray
    ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        objects = np.unique(groups)
        if len(objects) <= self.p:
            raise ValueError(f"leave-{self.p}-objects-out needs more than {self.p} objects")
        rng = np.random.default_rng(self.seed)
        seen: set[tuple[int, ...]] = set()
        for _ in range(20 * self.n_draws):
            if len(seen) == self.n_draws:
                return
            draw = tuple(sorted(rng.choice(objects, self.p, replace=False).tolist()))
            if draw in seen:
                continue
            seen.add(draw)
            held = np.isin(groups, draw)
            if len(np.unique(y[~held])) < 2:
                continue
            yield np.flatnonzero(~held), np.flatnonzero(held)


class ObjectCVLinearSVM:
    """scikit-learn style estimator: ``fit(X, y, groups)``, ``decision_function(X)``."""

    def __init__(
        self,
        Cs: Sequence[float] = DEFAULT_CS,
        n_draws: int = 20,
        p_out: int = 3,
        seed: int = 0,
        solver: str = "newton",
    ) -> None:
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        self.Cs = tuple(float(c) for c in Cs)
        self.n_draws = n_draws
        self.p_out = p_out
        self.seed = seed
        self.solver = solver

    def _svc(self, C: float) -> SquaredHingeSVM | LinearSVC:
        if self.solver == "newton":
            return SquaredHingeSVM(C)
        return LinearSVC(C=C, penalty="l2", dual=False, class_weight="balanced", max_iter=10000)

    def _pipeline(self, C: float) -> Pipeline:
        return make_pipeline(StandardScaler(), self._svc(C))

    def cv_scores(self, X: np.ndarray, y: np.ndarray, groups: np.ndarray) -> np.ndarray | None:
        """Pooled held-out AUC per C; ``None`` when no draw can score C.

        Holds out ``p_out`` objects per draw; on a small data set, where no such draw keeps both
        classes in training and gives both among the pooled held-out objects, it holds out fewer
        (down to one), with a warning. With fewer than two objects per class none can (None).
        """
        n_objects = len(np.unique(groups))
        for p_out in range(min(self.p_out, n_objects - 1), 0, -1):
            draws = list(LeavePObjectsOut(p_out, self.n_draws, self.seed).split(X, y, groups))
            held = np.concatenate([te for _, te in draws]) if draws else np.empty(0, int)
            if len(np.unique(y[held])) == 2:
                break
        else:
            return None
        if p_out < self.p_out:
            warnings.warn(
                f"only {n_objects} training objects: C chosen by leave-{p_out}-objects-out "
                f"instead of leave-{self.p_out}-objects-out",
                UserWarning,
                2,
            )
        # The Newton steps are small BLAS calls, ~10x slower on 2 BLAS threads than on one
        # (measured), and the draws already run on threads: one BLAS thread per draw.
        with threadpool_limits(1):
            decisions = self._held_out_decisions(X, y, draws)
        return np.array([roc_auc_score(y[held], np.concatenate(d)) for d in decisions])

    def _held_out_decisions(
        self, X: np.ndarray, y: np.ndarray, draws: list[tuple[np.ndarray, np.ndarray]]
    ) -> list[list[np.ndarray]]:
        """Per C, per draw: the held-out decision values of the pipeline fitted on the rest.

        The scaler does not depend on C, so each draw is standardised once for the whole grid
        (the same arrays the per-C pipeline computes; see `shortcuts`).
        """
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            # liblinear releases the GIL: draws run on threads (2.1x on 2 cores, measured),
            # their decisions kept in draw order, so the result does not depend on the threads.
            with ThreadPoolExecutor(cores.threads(len(draws))) as pool:
                per_draw = list(pool.map(lambda d: self._draw_decisions(X, y, *d), draws))
        return [[draw[j] for draw in per_draw] for j in range(len(self.Cs))]

    def _draw_decisions(
        self, X: np.ndarray, y: np.ndarray, tr: np.ndarray, te: np.ndarray
    ) -> list[np.ndarray]:
        """One draw, every C: held-out decision values, the draw standardised once."""
        scaler = StandardScaler().fit(X[tr])
        X_tr, X_te = scaler.transform(X[tr]), scaler.transform(X[te])
        return [self._svc(C).fit(X_tr, y[tr]).decision_function(X_te) for C in self.Cs]

    def fit(self, X: np.ndarray, y: np.ndarray, groups: np.ndarray) -> ObjectCVLinearSVM:
        X, y, groups = np.asarray(X, dtype=float), np.asarray(y), np.asarray(groups)
        if not np.isfinite(X).all():
            raise ValueError("ObjectCVLinearSVM.fit: X has NaN or infinite values")
        if len(np.unique(y)) < 2:
            raise ValueError("ObjectCVLinearSVM.fit: y needs both classes")
        self.cv_scores_ = self.cv_scores(X, y, groups) if len(self.Cs) > 1 else None
        if self.cv_scores_ is None:
            self.C_ = self.Cs[len(self.Cs) // 2]
            if len(self.Cs) > 1:
                warnings.warn(
                    f"no draw of held-out objects gives both classes; middle C={self.C_:g}",
                    UserWarning,
                    2,
                )
        else:
            self.C_ = self.Cs[int(np.argmax(self.cv_scores_))]
        with threadpool_limits(1):
            self.pipeline_ = self._pipeline(self.C_).fit(X, y)
        return self

    def decision_function(self, X: np.ndarray) -> np.ndarray:
        return self.pipeline_.decision_function(np.asarray(X, dtype=float))


@MODELS.register("linear_svm")
class LinearSVMModel(Model):
    """The `Model` face of `ObjectCVLinearSVM` (Table I rows A-F); groups = object ids."""

    learns_representation = False
    reads = ()  # no schedule, no loss: C is chosen by its own cross-validation
    storable = True  # state()/restore(): the scaler's and the SVM's fitted arrays (artifacts.py)
    onnx_refusal = "a linear SVM on scikit-learn arrays, not a torch network"

    def __init__(
        self,
        *,
        Cs: Sequence[float] | str | None = None,
        n_draws: int = 20,
        p_out: int = 3,
        seed: int = 0,
        solver: str = "newton",
    ) -> None:
        """``Cs``: a list of C values, None for DEFAULT_CS, or "authors" for AUTHORS_CS;
        ``solver``: "newton" (the optimum) or "liblinear" (LinearSVC's early stop)."""
        if isinstance(Cs, str) and Cs != "authors":
            raise ValueError(f"Cs must be a list of numbers, null or 'authors', got {Cs!r}")
        self.Cs = Cs
        self.n_draws = n_draws
        self.p_out = p_out
        self.seed = seed
        self.solver = solver
        grid = AUTHORS_CS if Cs == "authors" else DEFAULT_CS if Cs is None else Cs
        self.svm = ObjectCVLinearSVM(list(grid), n_draws, p_out, seed, solver)

    def fit(self, train: Instances, on_epoch: EpochCallback | None = None) -> History:
        self.svm.fit(train.X.reshape(len(train), -1), train.y, train.object_id)
        self.input_shape_ = tuple(train.X.shape[1:])
        return {}

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """No tensors; C and the fitted scaler and SVM as arrays: what ``restore`` takes."""
        scaler, svc = self.svm.pipeline_[0], self.svm.pipeline_[-1]
        arrays = {"C": np.float64(self.svm.C_), "mean": scaler.mean_, "scale": scaler.scale_}
        return {}, arrays | {"coef": svc.coef_, "intercept": svc.intercept_}

    def restore(
        self,
        input_shape: tuple[int, ...],
        tensors: Mapping[str, Any],
        arrays: Mapping[str, np.ndarray],
    ) -> LinearSVMModel:
        """The fitted model from ``state()``'s output; scores exactly as the one that wrote it."""
        width = int(np.prod(input_shape))
        shapes = {"mean": (width,), "scale": (width,), "coef": (1, width), "intercept": (1,)}
        for key, shape in shapes.items():
            if np.shape(arrays[key]) != shape:
                raise ValueError(f"{key}: shape {np.shape(arrays[key])}, expected {shape}")
        self.svm.C_ = float(arrays["C"])
        self.svm.pipeline_ = self.svm._pipeline(self.svm.C_)
        scaler, svc = self.svm.pipeline_[0], self.svm.pipeline_[-1]
        scaler.mean_, scaler.scale_ = arrays["mean"], arrays["scale"]
        svc.coef_, svc.intercept_, svc.classes_ = arrays["coef"], arrays["intercept"], np.arange(2)
        scaler.n_features_in_ = svc.n_features_in_ = width
        self.input_shape_ = tuple(input_shape)
        return self

    def decision_function(self, X: np.ndarray) -> np.ndarray:
        return self.svm.decision_function(X.reshape(len(X), -1))

    def head(self) -> Model:
        return clone(self)
