"""One run's Result: every stage's series and scalars, the parameters, the seed, the version,
particle snapshots, and the broken-bond record; saved to HDF5 with an XDMF file beside it so
ParaView opens the particles (radius, velocity, force) at the end of each stage."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Dict

import numpy as np

from .h5io import atomic_h5, open_h5
from .stages import StageResult

FORMAT = "pelletdem-result-1"


class ResultFileError(ValueError):
    """A result file that is missing, truncated, or not written by pelletdem."""


@dataclass
class Result:
    """A whole run. `stages` maps stage name to StageResult; `params` holds every input
    (plain JSON-able values); `snapshots` maps stage name to particle arrays."""

    params: dict
    seed: int
    version: str
    stages: Dict[str, StageResult] = field(default_factory=dict)
    snapshots: Dict[str, Dict[str, np.ndarray]] = field(default_factory=dict)

    def scalar(self, stage: str, name: str) -> float:
        """One scalar of one stage (SI units), e.g. scalar('diametral', 'sigma_f') in Pa."""
        return float(self.stages[stage].scalars[name])

    def series(self, stage: str, name: str) -> np.ndarray:
        """One time series of one stage, e.g. series('diametral', 'sigma_1') in Pa."""
        return self.stages[stage].series[name]

    def summary(self) -> dict:
        """The headline numbers: sigma_f (MPa), dL_f/D, the relaxed pellet's bulk density
        (kg/m^3; as a caliper reads it, from the outermost extents, and of its interior) and
        coordination number (bulk: the one to compare with the paper; and over every
        particle), particle count, seed and the wall time of each stage (s)."""
        out = {"seed": self.seed, "version": self.version}
        st = self.stages
        if "fill" in st:
            out["n_particles"] = int(st["fill"].scalars["n_particles"])
        if "diametral" in st:
            out["sigma_f_mpa"] = st["diametral"].scalars["sigma_f"] / 1e6
            out["dLf_D"] = st["diametral"].scalars["dLf_D"]
        if "relax" in st:
            rs = st["relax"].scalars
            out["relaxed_bulk_density"] = rs["bulk_density"]
            for key in ("bulk_density_extent", "bulk_density_core", "coordination_number_bulk"):
                if key in rs:  # results written before these were measured lack them
                    out["relaxed_" + key] = rs[key]
            out["relaxed_coordination_number"] = rs["coordination_number"]
        if "compact" in st:
            out["max_overlap_ratio"] = st["compact"].scalars["max_overlap_ratio"]
        out["wall_time_s"] = {k: round(v.wall_time_s, 3) for k, v in st.items()}
        out["steps"] = {k: int(v.steps) for k, v in st.items()}
        return out

    # --- HDF5 ------------------------------------------------------------------------------
    def save(self, path: str, xdmf: bool = True) -> str:
        """Write to HDF5 at `path` (atomically: a temporary name, then a rename, so a kill
        leaves any previous file whole) and, if `xdmf`, an XDMF file beside it. Returns path."""
        path = os.fspath(path)
        with atomic_h5(path, FORMAT) as f:
            self.write_group(f)
        if xdmf:
            write_xdmf(self, path)
        return path

    def write_group(self, f) -> None:
        """Everything into an open HDF5 file or group (a checkpoint keeps a Result in one)."""
        f.attrs["version"] = self.version
        f.attrs["seed"] = self.seed
        f.attrs["params"] = json.dumps(self.params, default=_jsonable)
        for name, st in self.stages.items():
            g = f.create_group(f"stages/{name}")
            g.attrs["wall_time_s"] = st.wall_time_s
            g.attrs["steps"] = st.steps
            g.attrs["order"] = list(self.stages).index(name)
            sc = g.create_group("scalars")
            for k, v in st.scalars.items():
                sc.attrs[k] = float(v)
            se = g.create_group("series")
            for k, v in st.series.items():
                se.create_dataset(k, data=np.asarray(v))
        write_snapshots(f, self.snapshots)

    @classmethod
    def load(cls, path: str) -> "Result":
        """Read a Result written by `save`. A missing, truncated or foreign file raises
        ResultFileError naming the file and what is wrong."""
        with open_h5(path, FORMAT, ResultFileError, "pelletdem result") as f:
            try:
                return cls.read_group(f)
            except (OSError, KeyError, ValueError, TypeError) as e:
                # HDF5 notices a cut-off end when opening, damage inside only when reading.
                raise ResultFileError(f"{path}: damaged pelletdem result "
                                      f"({type(e).__name__}: {e})") from None

    @classmethod
    def read_group(cls, f) -> "Result":
        """The Result in an open pelletdem HDF5 file (KeyError/OSError when it is damaged)."""
        res = cls(params=json.loads(f.attrs["params"]), seed=int(f.attrs["seed"]),
                  version=str(f.attrs["version"]))
        groups = f.get("stages", {})
        for name in sorted(groups, key=lambda n: groups[n].attrs["order"]):
            g = groups[name]
            res.stages[name] = StageResult(
                name, series={k: g["series"][k][()] for k in g["series"]},
                scalars={k: float(v) for k, v in g["scalars"].attrs.items()},
                wall_time_s=float(g.attrs["wall_time_s"]), steps=int(g.attrs["steps"]))
        res.snapshots.update(read_snapshots(f))
        return res


def write_snapshots(f, snapshots: Dict[str, Dict[str, np.ndarray]]) -> None:
    """Particle snapshots (stage -> arrays and scalar time) into group `snapshots` of `f`."""
    for name, snap in snapshots.items():
        g = f.create_group(f"snapshots/{name}")
        g.attrs["order"] = list(snapshots).index(name)
        for k, v in snap.items():
            if np.ndim(v) == 0:
                g.attrs[k] = float(v)
            else:
                g.create_dataset(k, data=np.asarray(v))


def read_snapshots(f) -> Dict[str, Dict[str, np.ndarray]]:
    """The snapshots written by write_snapshots, in their original order."""
    out = {}
    snaps = f.get("snapshots", {})
    for name in sorted(snaps, key=lambda n: snaps[n].attrs["order"]):
        g = snaps[name]
        d = {k: g[k][()] for k in g}
        d.update({k: float(v) for k, v in g.attrs.items() if k != "order"})
        out[name] = d
    return out


def _jsonable(v):
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON-able: {type(v)}")


def write_xdmf(result: Result, h5_path: str) -> str:
    """An XDMF file beside `h5_path` with one grid per snapshot (a temporal collection), so
    ParaView shows the particles with radius, velocity and force. Returns the XDMF path."""
    h5_name = os.path.basename(h5_path)
    xdmf_path = os.path.splitext(h5_path)[0] + ".xdmf"
    grids = []
    for k, (name, snap) in enumerate(result.snapshots.items()):
        n = len(snap["radius"])
        base = f"{h5_name}:/snapshots/{name}"
        attrs = []
        for key, label, vec in (("radius", "radius", False), ("velocity", "velocity", True),
                                ("force", "force", True), ("angular_velocity", "angular_velocity", True)):
            if key not in snap:
                continue
            dims = f"{n} 3" if vec else f"{n}"
            attrs.append(
                f'        <Attribute Name="{label}" AttributeType="{"Vector" if vec else "Scalar"}" Center="Node">\n'
                f'          <DataItem Dimensions="{dims}" NumberType="Float" Precision="8" Format="HDF">'
                f'{base}/{key}</DataItem>\n'
                f'        </Attribute>')
        grids.append(
            f'      <Grid Name="{name}" GridType="Uniform">\n'
            f'        <Time Value="{k}"/>\n'
            f'        <Topology TopologyType="Polyvertex" NumberOfElements="{n}"/>\n'
            f'        <Geometry GeometryType="XYZ">\n'
            f'          <DataItem Dimensions="{n} 3" NumberType="Float" Precision="8" Format="HDF">'
            f'{base}/position</DataItem>\n'
            f'        </Geometry>\n' + "\n".join(attrs) + "\n      </Grid>")
    text = ('<?xml version="1.0" ?>\n<Xdmf Version="3.0">\n  <Domain>\n'
            '    <Grid Name="stages" GridType="Collection" CollectionType="Temporal">\n'
            + "\n".join(grids) + "\n    </Grid>\n  </Domain>\n</Xdmf>\n")
    tmp = xdmf_path + ".tmp"
    with open(tmp, "w") as fh:
        fh.write(text)
    os.replace(tmp, xdmf_path)
    return xdmf_path
