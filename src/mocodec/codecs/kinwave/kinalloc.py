"""Quantiser steps per joint from a small convex program (kinwave.md, "what mattered" 3).

Model: the rotation error ``e_j`` (radians) of joint ``j`` moves every point below it. In open
loop it rotates the whole subtree, so a point ``p`` moves by ``e_j`` times its distance along
the chain; in closed loop (children restore their original global orientation) it only
shifts the subtree by ``e_j`` times the length of the bone from ``j`` towards ``p``, and the
shell around ``j``'s own bone (points 3 cm off its axes) by ``e_j`` times 3 cm. Errors of
independent joints add in quadrature; a joint with ``m`` coded angles of step ``s`` has
``e^2 ~ m s^2``, the root translation (3 channels, step ``s_T`` cm) moves everything.

The rate of a joint falls by ``m log2 s`` bits per frame (high-rate approximation), so:

* ``mean`` (mean joint error): minimise rate subject to the mean over points of the error's
  norm, ``sqrt`` of the squared error (convex in ``log u``), starting from the closed form
  that bounds the mean *squared* error instead, ``s_j ~ 1 / sqrt(mean_p lever_jp^2)``: the
  norm lets points that already move a lot take more error (smaller files than the closed
  form: docs/kinwave.md);
* ``joint`` / ``shell`` (max error): subject to every point's (every shell's) squared error
  at most 1 — a convex program in ``u = s^2``, solved through its dual by multiplicative price
  updates (:func:`_max_program`).

Steps are scaled so that the model's error bound is 1 cm; the codec scales them to the
requested bound and verifies the real error.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.optimize import minimize

from mocodec.kernels import kernel
from mocodec.skeleton import Skeleton

MODES = ("shell", "joint", "mean")
#: The max program's dual rounds stop where the duality gap is under MAX_GAP of the rate
#: weights' sum (the steps are then within about that share of the optimum's), checked every
#: GAP_EVERY rounds, or after MAX_ROUNDS.
MAX_GAP = 1e-6
GAP_EVERY = 8
MAX_ROUNDS = 20_000
SHELL_CM = 3.0
_DEG = np.pi / 180.0


def levers(skeleton: Skeleton, closed_loop: bool) -> np.ndarray:
    """``(joints, joints)`` cm: how far a unit rotation error of joint ``j`` (rows) moves the
    pivot of joint ``p`` (columns)."""
    parents = skeleton.parents
    cm = 100.0 / skeleton.units_per_metre
    bone = np.linalg.norm(skeleton.offsets, axis=1) * cm
    n = len(parents)
    out = np.zeros((n, n))
    for p in range(n):
        child, j, path = p, parents[p], bone[p]
        while j >= 0:
            out[j, p] = path if not closed_loop else bone[child]
            child, j = j, parents[j]
            path += bone[child] if j >= 0 else 0.0
    return out


def points(skeleton: Skeleton, closed_loop: bool, mode: str) -> np.ndarray:
    """Squared levers ``(joints, points)`` of the points the mode bounds."""
    lev = levers(skeleton, closed_loop)
    if mode != "shell":
        return lev**2
    has_bone = np.array([len(c) > 0 for c in skeleton.children])
    shell = lev[:, has_bone] ** 2
    own = np.flatnonzero(has_bone)
    # the shell of joint b turns with b and with every ancestor (open loop) / b alone (closed)
    for k, b in enumerate(own):
        shell[b, k] += SHELL_CM**2
        if not closed_loop:
            j = skeleton.parents[b]
            while j >= 0:
                shell[j, k] += SHELL_CM**2 + 2 * SHELL_CM * lev[j, b]
                j = skeleton.parents[j]
    return shell


@lru_cache(maxsize=64)
def steps(
    skeleton: Skeleton, angles: tuple[int, ...], translations: int, mode: str, closed_loop: bool
) -> tuple[np.ndarray, float]:
    """Rotation steps per joint (degrees; NaN for joints without coded angles) and the
    translation step (cm) whose modelled error bound is 1 cm. ``angles[j]`` is the number of
    coded angles of joint ``j``; ``translations`` the number of coded translation channels."""
    if mode not in MODES:
        raise ValueError(f"unknown allocation mode {mode!r} (one of {', '.join(MODES)})")
    m = np.asarray(angles, dtype=float)
    coded = np.flatnonzero(m > 0)
    sq = points(skeleton, closed_loop, mode)
    # per variable (coded joints, then the translation): rate weight and squared lever per point
    weight = np.append(m[coded], translations) if translations else m[coded]
    lever2 = sq[coded] * (m[coded, None] * _DEG**2)
    if translations:
        lever2 = np.vstack([lever2, np.full(sq.shape[1], float(translations))])
    lever2 = lever2[:, lever2.max(axis=0) > 0] if lever2.size else lever2
    if weight.size == 0 or lever2.shape[1] == 0:
        return np.full(len(m), np.nan), 1.0
    mean = lever2.mean(axis=1)
    useful = mean > 0
    u = np.where(useful, weight / (weight[useful].sum() * np.where(useful, mean, 1.0)), 1.0)
    if useful.any():
        if mode == "mean":
            u[useful] = _mean_program(weight[useful], lever2[useful], u[useful])
        else:
            u[useful] = _max_program(weight[useful], lever2[useful])
    s = np.sqrt(u)
    rot = np.full(len(m), np.nan)
    rot[coded] = s[: coded.size]
    return rot, float(s[-1]) if translations else 1.0


def _most_rate_saved(weight: np.ndarray, x0: np.ndarray, slack, slack_jac, maxiter: int) -> np.ndarray | None:
    """x = log u maximising sum w x subject to ``slack(x) >= 0`` (SLSQP from ``x0``), or None if
    the solver returned non-finite values."""
    res = minimize(
        lambda x: (-weight @ x, -weight),
        x0,
        jac=True,
        method="SLSQP",
        constraints=[{"type": "ineq", "fun": slack, "jac": slack_jac}],
        options={"maxiter": maxiter, "ftol": 1e-10},
    )
    return res.x if np.isfinite(res.x).all() else None


def _mean_program(weight: np.ndarray, lever2: np.ndarray, start: np.ndarray) -> np.ndarray:
    """maximise sum w log u subject to mean_p sqrt(lever2^T u) <= 1, in x = log u."""

    def slack(x):
        return 1.0 - np.sqrt(lever2.T @ np.exp(x)).mean()

    def slack_jac(x):
        v = lever2.T @ np.exp(x)
        return -(lever2 * np.exp(x)[:, None]) @ (0.5 / np.sqrt(np.maximum(v, 1e-300)) / v.size)

    x = _most_rate_saved(weight, np.log(start), slack, slack_jac, 300)
    u = start if x is None else np.exp(x)
    return u / np.sqrt(lever2.T @ u).mean() ** 2  # the bound met whatever SLSQP returned


@kernel
def _dual_rounds(weight, lever2, start):
    """:func:`_max_program`'s prices: the rounds from equal prices ``start`` (compiled: a round
    is two small products, and a skeleton can take a thousand). The gap is the dual's value
    ``sum w log(w / (lever2 lam)) - sum w + sum lam`` less the rate of the rounds' steps scaled
    to be feasible, ``sum w log(u / max load)``."""
    joints, points = lever2.shape
    prices = np.full(points, start)
    u = np.empty(joints)
    load = np.empty(points)
    total_weight = weight.sum()
    for done in range(MAX_ROUNDS):
        dual = prices.sum() - total_weight
        for j in range(joints):
            total = 0.0
            for p in range(points):
                total += lever2[j, p] * prices[p]
            total = max(total, 1e-300)
            u[j] = weight[j] / total
            dual += weight[j] * np.log(weight[j] / total)
        for p in range(points):
            total = 0.0
            for j in range(joints):
                total += lever2[j, p] * u[j]
            load[p] = total
        if done % GAP_EVERY == 0:
            primal = -total_weight * np.log(max(load.max(), 1e-300))
            for j in range(joints):
                primal += weight[j] * np.log(u[j])
            if dual - primal <= MAX_GAP * total_weight:
                break
        for p in range(points):  # over-relaxed (load^1.5): a third fewer rounds, the same optimum
            prices[p] *= load[p] * np.sqrt(load[p])
    return prices


def _max_program(weight: np.ndarray, lever2: np.ndarray) -> np.ndarray:
    """maximise sum w log u subject to lever2^T u <= 1 (every point), by its dual: with a price
    ``lam_p >= 0`` per point, ``u_j = w_j / (lever2 lam)_j`` (the optimality condition), and
    each price scaled by how far its point's constraint is from tight, ``lam_p *= (lever2^T
    u)_p^1.5``, from equal prices until the duality gap is under MAX_GAP of the weights. Each round
    costs two small products (time against SLSQP: docs/kinwave.md)."""
    prices = _dual_rounds(
        np.ascontiguousarray(weight, dtype=np.float64),
        np.ascontiguousarray(lever2, dtype=np.float64),
        weight.sum() / lever2.shape[1],
    )
    u = weight / np.maximum(lever2 @ prices, 1e-300)
    return u / max((lever2.T @ u).max(), 1e-300)  # feasible wherever the rounds stopped
