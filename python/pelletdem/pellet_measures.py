"""What the stages measure of a pellet in its world: its main piece (the largest group of
particles joined by contacts or intact bonds, without the crumbs it shed), its outermost
extents, its size and density as a caliper reads them (:mod:`pelletdem.caliper`), its bulk
coordination number, and the inertia number that tells a quasi-static loading."""
from __future__ import annotations

from typing import Optional

import numpy as np

from . import caliper
from .world import World

__all__ = ["largest_group", "main_piece", "pellet_extent", "measure", "bulk_coordination_number",
           "largest_cluster_fraction", "inertia_number"]


def largest_group(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Boolean mask of the largest group of the n particles connected through pairs (i, j)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if n == 0:
        return np.zeros(0, dtype=bool)
    _, labels = connected_components(coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)), directed=False)
    return labels == np.argmax(np.bincount(labels))


def main_piece(world: World) -> np.ndarray:
    """Boolean mask of the particles in the largest group connected by contacts or intact
    bonds: the pellet, without loose particles it may have shed."""
    c, b = world.contacts(), world.bonds()
    intact = b["mode"] == 0
    i = np.concatenate([c["i"], b["i"][intact]]).astype(np.int64)
    j = np.concatenate([c["j"], b["j"][intact]]).astype(np.int64)
    return largest_group(world.n, i, j)


def pellet_extent(world: World, mask: Optional[np.ndarray] = None) -> tuple:
    """(diameter, height, centre x, centre y) of the outermost surfaces of the particles in
    `mask` (all by default), m: one protruding sphere sets them (see :func:`measure`)."""
    x = np.asarray(world.x)
    r = np.asarray(world.r)
    if mask is not None:
        x, r = x[mask], r[mask]
    cx, cy = x[:, 0].mean(), x[:, 1].mean()
    rho = np.hypot(x[:, 0] - cx, x[:, 1] - cy) + r
    height = (x[:, 2] + r).max() - (x[:, 2] - r).min()
    return 2.0 * rho.max(), height, cx, cy


def measure(world: World, mask: np.ndarray) -> caliper.PelletSize:
    """Size and density of the particles in `mask` (the pellet's main piece) as a caliper and
    a balance read them (:mod:`pelletdem.caliper`; masses unscaled by the world's density
    scale)."""
    return caliper.pellet_size(np.asarray(world.x)[mask], np.asarray(world.r)[mask],
                               np.asarray(world.m)[mask] / world.density_scale)


def bulk_coordination_number(world: World, mask: np.ndarray, size: caliper.PelletSize) -> float:
    """Mean contacts per particle over the particles of `mask` that `size` counts as bulk
    (size.bulk_depth or more below the enclosed surface)."""
    c = world.contacts()
    z = caliper.contacts_per_particle(world.n, c["i"], c["j"])
    return float(z[np.nonzero(mask)[0][size.bulk]].mean())


def largest_cluster_fraction(n: int, i: np.ndarray, j: np.ndarray) -> float:
    """Fraction of the n particles in the largest group connected through the pairs (i, j)."""
    return float(largest_group(n, i, j).sum() / n) if n > 0 else 0.0


def inertia_number(strain_rate, d_mean: float, density: float, pressure) -> np.ndarray:
    """I = strain_rate d sqrt(rho / p) (dimensionless); inf where p <= 0."""
    p = np.asarray(pressure, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(p > 0, np.asarray(strain_rate) * d_mean * np.sqrt(density / np.where(p > 0, p, 1.0)), np.inf)
