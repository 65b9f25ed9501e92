"""Crack maps of broken bonds, like the paper's Fig. 16, and where the cracks lie.

A broken bond is drawn at its centre at the moment it broke (``World.broken_bonds()``:
"position", m; "mode", 1 tension / 2 shear). Geometry follows the stages: the pellet's axis is
z, the plates of the diametral test are normal to y, so the loaded diameter is the line x = x_c
in the x-y plane. Lengths are in metres throughout; plots label them in mm.

Figures are drawn on matplotlib's Agg canvas directly (``matplotlib.figure.Figure``), so
nothing here changes the pyplot backend of a notebook that imports this module.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping, Optional, Sequence, Tuple

import numpy as np

__all__ = ["crack_map", "plot_crack_maps", "broken_fraction_by_region", "band_area_fraction",
           "MODE_COLORS", "MODE_NAMES"]

MODE_COLORS = {1: "tab:red", 2: "tab:blue"}
MODE_NAMES = {1: "tension", 2: "shear"}
_AXES = {"x": 0, "y": 1, "z": 2}


def _broken_arrays(broken: Mapping) -> Tuple[np.ndarray, np.ndarray]:
    """(positions (M, 3) m, modes (M,)) from a broken-bond record.

    Accepts ``World.broken_bonds()`` ("position", "mode") and the diametral stage's series
    ("broken_position", "broken_mode").
    """
    if "position" in broken:
        pos, mode = broken["position"], broken.get("mode")
    elif "broken_position" in broken:
        pos, mode = broken["broken_position"], broken.get("broken_mode")
    else:
        raise ValueError("broken must hold 'position' (or 'broken_position'), (M, 3) m")
    pos = np.asarray(pos, dtype=float).reshape(-1, 3)
    mode = np.ones(len(pos), dtype=int) if mode is None else np.asarray(mode, dtype=int).reshape(-1)
    if len(mode) != len(pos):
        raise ValueError(f"broken: {len(pos)} positions but {len(mode)} modes")
    if not np.all(np.isfinite(pos)):
        raise ValueError("broken: positions must be finite (m)")
    return pos, mode


def _pellet_geometry(positions, radii, axis_center=None, diameter=None, height=None):
    """Axis centre (x, y), diameter, bottom z and height of the particle assembly, m."""
    x = np.asarray(positions, dtype=float).reshape(-1, 3)
    r = np.zeros(len(x)) if radii is None else np.broadcast_to(np.asarray(radii, dtype=float), (len(x),))
    if len(x) == 0:
        raise ValueError("positions must hold at least one particle, (N, 3) m")
    if axis_center is None:
        axis_center = (float(x[:, 0].mean()), float(x[:, 1].mean()))
    cx, cy = float(axis_center[0]), float(axis_center[1])
    if diameter is None:
        diameter = 2.0 * float((np.hypot(x[:, 0] - cx, x[:, 1] - cy) + r).max())
    z_lo = float((x[:, 2] - r).min())
    if height is None:
        height = float((x[:, 2] + r).max()) - z_lo
    if not (diameter > 0 and height > 0):
        raise ValueError(f"pellet diameter ({diameter} m) and height ({height} m) must be > 0")
    return (cx, cy), float(diameter), z_lo, float(height)


def band_area_fraction(band: float = 0.3) -> float:
    """Share of a circle's area within a band of width `band` D centred on a diameter.

    The fraction of cracks a band would hold if cracks were spread uniformly over the section
    (0.376 for the default 0.3 D): the reference to compare `broken_fraction_by_region` with.
    """
    if not 0.0 <= band <= 1.0:
        raise ValueError(f"band = {band} is out of range: allowed 0 <= band <= 1 (a fraction of D)")
    a = band  # half-width over the radius: (band D / 2) / (D / 2)
    return (2.0 / math.pi) * (math.asin(a) + a * math.sqrt(1.0 - a * a))


def broken_fraction_by_region(broken: Mapping, positions=None, radii=None, axis_center=None,
                              diameter: Optional[float] = None, loaded_axis: str = "y",
                              band: float = 0.3) -> dict:
    """Fraction of broken bonds whose centre lies near the loaded diameter.

    The loaded diameter is the pellet's diameter along `loaded_axis` ('x' or 'y'; the plates
    are normal to it) through the axis at `axis_center` (x, y, m). A bond counts when its
    centre is within band * D / 2 of that line (a band of width `band` D, 0.3 D by default),
    measured across it in the x-y plane, whatever its z. `positions` (N, 3) m and `radii`
    (N,) m give the centre and diameter D when they are not given (positions may be None
    when both are given).

    Returns a dict: fraction (of broken bonds in the band; nan if none broke), n_band,
    n_total, band_width (m), diameter (m), uniform_fraction (the fraction a uniform spread
    over the circular section would give, see band_area_fraction) and concentration
    (fraction / uniform_fraction: > 1 when the cracks gather along the loaded diameter).
    """
    if loaded_axis not in ("x", "y"):
        raise ValueError(f"loaded_axis = {loaded_axis!r}: allowed 'x' or 'y' (the pellet axis is z)")
    if not 0.0 < band <= 1.0:
        raise ValueError(f"band = {band} is out of range: allowed 0 < band <= 1 (a fraction of D)")
    if positions is None:
        if axis_center is None or diameter is None:
            raise ValueError("give positions (N, 3) m, or both axis_center and diameter")
        (cx, cy), d = (float(axis_center[0]), float(axis_center[1])), float(diameter)
        if not d > 0:
            raise ValueError(f"diameter = {d} m must be > 0")
    else:
        (cx, cy), d, _, _ = _pellet_geometry(positions, radii, axis_center, diameter, height=1.0)
    pos, _ = _broken_arrays(broken)
    # Across the loaded diameter: x when the load is along y, y when along x.
    across = pos[:, 0] - cx if loaded_axis == "y" else pos[:, 1] - cy
    half = 0.5 * band * d
    n_band = int(np.count_nonzero(np.abs(across) <= half))
    n = len(pos)
    frac = n_band / n if n else float("nan")
    uni = band_area_fraction(band)
    return {"fraction": frac, "n_band": n_band, "n_total": n, "band_width": 2.0 * half,
            "diameter": d, "uniform_fraction": uni, "concentration": frac / uni}


def _new_figure(figsize=(11.0, 5.0)):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def crack_map(broken: Mapping, positions, radii, axis_center=None, height: Optional[float] = None,
              ax=None, mode_colors: Mapping[int, str] = MODE_COLORS, slab: Optional[float] = None,
              loaded_axis: str = "y", band: Optional[float] = 0.3, show_particles: bool = True,
              title: Optional[str] = None):
    """Draw the broken bonds as the paper's Fig. 16: a mid-plane section and a 3D view.

    broken: ``World.broken_bonds()`` (or the diametral series' broken_position/broken_mode).
    positions (N, 3) m, radii (N,) m: the particles at the time of the map (for the outline,
    the mid-plane and the grey section of the particles cut by it).
    axis_center: (x, y) of the pellet axis, m (default: the particles' mean).
    height: pellet height, m (default: from the particles); the mid-plane is at
    z = z_bottom + height / 2 with z_bottom the lowest particle surface.
    slab: half-thickness of the slab around the mid-plane whose bonds the section shows, m
    (default: the mean particle diameter).
    ax: None (a new figure with both panels), a (section_axes, axes_3d) pair, or one Axes
    (a 3D Axes gets the 3D view, a 2D one the section).
    mode_colors: colour per mode (1 tension, 2 shear). loaded_axis: direction of the load
    ('x' or 'y'); the loaded diameter is drawn dashed, with the band of width `band` D
    (None: no band).

    Returns (figure, (section_axes or None, axes_3d or None)).
    """
    pos, mode = _broken_arrays(broken)
    xp = np.asarray(positions, dtype=float).reshape(-1, 3)
    rp = np.broadcast_to(np.asarray(radii, dtype=float), (len(xp),))
    (cx, cy), d, z_lo, h = _pellet_geometry(xp, rp, axis_center, None, height)
    z_mid = z_lo + 0.5 * h
    if slab is None:
        slab = 2.0 * float(rp.mean())
    if not slab > 0:
        raise ValueError(f"slab = {slab} m must be > 0")

    ax2d = ax3d = None
    if ax is None:
        fig = _new_figure()
        ax2d = fig.add_subplot(1, 2, 1)
        ax3d = fig.add_subplot(1, 2, 2, projection="3d")
    elif isinstance(ax, (tuple, list)):
        ax2d, ax3d = ax
        fig = (ax2d or ax3d).figure
    elif hasattr(ax, "zaxis"):
        ax3d, fig = ax, ax.figure
    else:
        ax2d, fig = ax, ax.figure
    mm = 1e3
    modes = sorted(set(int(m) for m in mode) | set(mode_colors))

    if ax2d is not None:
        from matplotlib.collections import EllipseCollection
        from matplotlib.patches import Circle, Rectangle

        if show_particles and len(xp):
            dz = xp[:, 2] - z_mid
            cut = np.abs(dz) < rp
            rc = np.sqrt(rp[cut] ** 2 - dz[cut] ** 2)
            ax2d.add_collection(EllipseCollection(
                2 * rc * mm, 2 * rc * mm, 0.0, units="xy", offsets=xp[cut, :2] * mm,
                offset_transform=ax2d.transData, facecolors="0.88", edgecolors="0.7", linewidths=0.3))
        outline = Circle((cx * mm, cy * mm), 0.5 * d * mm, fill=False, color="k", lw=1.2)
        ax2d.add_patch(outline)
        if band is not None:
            w = band * d * mm
            if loaded_axis == "y":
                rect = Rectangle((cx * mm - 0.5 * w, (cy - 0.5 * d) * mm), w, d * mm,
                                 color="0.5", alpha=0.12, lw=0)
                ax2d.plot([cx * mm] * 2, [(cy - 0.5 * d) * mm, (cy + 0.5 * d) * mm], "k--", lw=0.8)
            else:
                rect = Rectangle(((cx - 0.5 * d) * mm, cy * mm - 0.5 * w), d * mm, w,
                                 color="0.5", alpha=0.12, lw=0)
                ax2d.plot([(cx - 0.5 * d) * mm, (cx + 0.5 * d) * mm], [cy * mm] * 2, "k--", lw=0.8)
            ax2d.add_patch(rect)
            rect.set_clip_path(outline)  # the band inside the pellet only
        in_slab = np.abs(pos[:, 2] - z_mid) <= slab
        for m in modes:
            sel = in_slab & (mode == m)
            ax2d.scatter(pos[sel, 0] * mm, pos[sel, 1] * mm, s=10, color=mode_colors.get(m, "k"),
                         label=f"{MODE_NAMES.get(m, f'mode {m}')} ({int(sel.sum())})", zorder=3)
        pad = 0.08 * d * mm
        ax2d.set_xlim((cx - 0.5 * d) * mm - pad, (cx + 0.5 * d) * mm + pad)
        ax2d.set_ylim((cy - 0.5 * d) * mm - pad, (cy + 0.5 * d) * mm + pad)
        ax2d.set_aspect("equal")
        ax2d.set_xlabel("x (mm)")
        ax2d.set_ylabel("y (mm)")
        ax2d.set_title(f"(a) section z = {z_mid * mm:.2f} mm ± {slab * mm:.2f} mm")
        ax2d.legend(loc="upper right", fontsize=8)

    if ax3d is not None:
        t = np.linspace(0.0, 2.0 * math.pi, 97)
        for z in (z_lo, z_lo + h):
            ax3d.plot((cx + 0.5 * d * np.cos(t)) * mm, (cy + 0.5 * d * np.sin(t)) * mm,
                      np.full_like(t, z * mm), color="0.4", lw=0.8)
        for a in np.linspace(0.0, 2.0 * math.pi, 9)[:-1]:
            px, py = cx + 0.5 * d * math.cos(a), cy + 0.5 * d * math.sin(a)
            ax3d.plot([px * mm] * 2, [py * mm] * 2, [z_lo * mm, (z_lo + h) * mm], color="0.8", lw=0.6)
        for m in modes:
            sel = mode == m
            ax3d.scatter(pos[sel, 0] * mm, pos[sel, 1] * mm, pos[sel, 2] * mm, s=6,
                         color=mode_colors.get(m, "k"), label=MODE_NAMES.get(m, f"mode {m}"),
                         depthshade=False)
        ax3d.set_xlabel("x (mm)")
        ax3d.set_ylabel("y (mm)")
        ax3d.set_zlabel("z (mm)")
        ax3d.set_title(f"(b) all {len(pos)} broken bonds")
        try:
            ax3d.set_box_aspect((d, d, h))
        except AttributeError:  # very old matplotlib
            pass

    if title:
        fig.suptitle(title)
    return fig, (ax2d, ax3d)


def _unpack(result_like):
    """(broken dict, positions, radii, extra kwargs) from the objects the stages produce."""
    # A World (or anything with broken_bonds() and positions()).
    if hasattr(result_like, "broken_bonds") and hasattr(result_like, "positions"):
        return (result_like.broken_bonds(), np.asarray(result_like.positions()),
                np.asarray(result_like.radii()), {})
    # A Pellet: its world.
    if hasattr(result_like, "world") and hasattr(result_like.world, "broken_bonds"):
        return _unpack(result_like.world)
    if isinstance(result_like, Mapping):
        d = dict(result_like)
        broken = d.get("broken", d)
        pos = d.get("positions", d.get("position_particles"))
        rad = d.get("radii")
        if pos is None or rad is None:
            raise ValueError("a dict for plot_crack_maps needs 'positions' (N, 3) m and 'radii' (N,) m")
        extra = {k: d[k] for k in ("axis_center", "height") if k in d}
        return broken, np.asarray(pos), np.asarray(rad), extra
    # A StageResult of the diametral stage plus a snapshot: (result, snapshot dict).
    if isinstance(result_like, Sequence) and len(result_like) == 2:
        res, snap = result_like
        series = getattr(res, "series", res)
        extra = {}
        scalars = getattr(res, "scalars", {})
        if "height" in scalars:
            extra["height"] = float(scalars["height"])
        return series, np.asarray(snap["position"]), np.asarray(snap["radius"]), extra
    raise TypeError("plot_crack_maps takes a World, a Pellet, a dict with broken/positions/radii, "
                    "or a (StageResult, snapshot) pair")


def plot_crack_maps(result_like, path, title: Optional[str] = None, dpi: int = 150, **kwargs) -> Path:
    """Write a PNG with the section (a) and the 3D view (b) of the broken bonds.

    result_like: a World or Pellet (its broken bonds and current particles); a dict with
    'broken' (a broken-bond record), 'positions' (N, 3) m, 'radii' (N,) m and optionally
    'axis_center' (m) and 'height' (m); or a (diametral StageResult, snapshot) pair, the
    snapshot being ``Pellet.snapshots['diametral']``. Other keyword arguments go to
    `crack_map`. Returns the path written.
    """
    broken, pos, rad, extra = _unpack(result_like)
    extra.update(kwargs)
    fig, _ = crack_map(broken, pos, rad, title=title, **extra)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    return path
