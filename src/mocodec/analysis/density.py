"""Probability densities (000 §5.2.3): the PDF of a DOF (fig. 5-6), the PDF of the first
difference of a group (fig. 5-7, "Laplace-like") and the joint PDF of a pair of DOFs
(fig. 5-9 to 5-11)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Density:
    edges: np.ndarray  # bin edges
    density: np.ndarray  # integrates to 1 over the bins

    @property
    def centres(self) -> np.ndarray:
        return 0.5 * (self.edges[1:] + self.edges[:-1])


def pdf(values: np.ndarray, bins: int = 64, value_range: tuple[float, float] | None = None) -> Density:
    """Histogram estimate of the PDF of all ``values``."""
    values = np.asarray(values, dtype=np.float64).ravel()
    density, edges = np.histogram(values, bins=bins, range=value_range, density=True)
    return Density(edges, density)


def first_difference(channels: np.ndarray) -> np.ndarray:
    """d(n) = theta(n) - theta(n - 1) per column (§5.2.3, "derivative PDF")."""
    return np.diff(np.asarray(channels, dtype=np.float64), axis=0)


def joint_pdf(
    x: np.ndarray, y: np.ndarray, bins: int = 64, value_range=((-180.0, 180.0), (-180.0, 180.0))
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """2-D histogram density of a DOF pair (fig. 5-9): ``(density, x_edges, y_edges)``."""
    density, xe, ye = np.histogram2d(np.ravel(x), np.ravel(y), bins=bins, range=value_range, density=True)
    return density, xe, ye


@dataclass(frozen=True)
class ShapeFit:
    """Which of Laplace and Gaussian describes a sample better (mean log-likelihood)."""

    laplace_loglik: float
    gauss_loglik: float
    excess_kurtosis: float  # 0 for a Gaussian, 3 for a Laplace density

    @property
    def best(self) -> str:
        return "laplace" if self.laplace_loglik > self.gauss_loglik else "gauss"


def laplace_or_gauss(values: np.ndarray) -> ShapeFit:
    """Maximum-likelihood Laplace and Gaussian fits of a sample, compared."""
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    sigma = v.std()
    b = np.mean(np.abs(v - np.median(v)))
    if v.size < 2 or sigma == 0 or b == 0:
        return ShapeFit(float("nan"), float("nan"), float("nan"))
    gauss = -0.5 * np.log(2 * np.pi * sigma**2) - 0.5
    laplace = -np.log(2 * b) - 1.0
    kurt = np.mean((v - v.mean()) ** 4) / sigma**4 - 3.0
    return ShapeFit(float(laplace), float(gauss), float(kurt))
