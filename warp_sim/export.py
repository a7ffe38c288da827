"""Recorded runs in formats other tools open: USD (usdview, Blender, Omniverse) and CSV.

USD layout (y up, metres, one time code per recorded frame, ``timeCodesPerSecond`` = recorded
frames per simulated second, so players run it in real time):

    /World                       Xform
    /World/Terrain               Mesh, a grid over the bodies' range (absent without terrain)
    /World/Bodies/body_000000    Sphere (radius) or Cube (size 2, scaled by the half extents),
                                 xformOps translate and orient time-sampled per frame, scale fixed

CSV: one row per frame and body, ``frame,time,body,x,y,z,qx,qy,qz,qw`` (quaternions x y z w,
as everywhere in this package).  USD needs ``usd-core`` (``pip install "warp-sim[usd]"``).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from .replay import terrain_from_record
from .terrain import FourierTerrain, PlaneTerrain
from .types import SHAPE_SPHERE

CSV_HEADER = ("frame", "time", "body", "x", "y", "z", "qx", "qy", "qz", "qw")


def export_csv(record: dict, path) -> int:
    """Write per-body tracks; returns the number of data rows (frames x bodies)."""
    pos, quat, times = record["position"], record["orientation"], record["time"]
    f, n = pos.shape[:2]
    frame = np.repeat(np.arange(f), n)
    body = np.tile(np.arange(n), f)
    with open(path, "w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow(CSV_HEADER)
        # %.9g keeps float32 exact and the times of long runs distinct
        for i, b, row_pos, row_q in zip(frame, body, pos.reshape(-1, 3), quat.reshape(-1, 4), strict=True):
            writer.writerow([int(i), f"{times[i]:.9g}", int(b), *(f"{v:.9g}" for v in row_pos),
                             *(f"{v:.9g}" for v in row_q)])
    return f * n


def terrain_grid(terrain, lo: np.ndarray, hi: np.ndarray, resolution: int):
    """Vertices (R+1)^2 x 3 and quad indices of the terrain's height over [lo, hi] in x and z."""
    xs = np.linspace(lo[0], hi[0], resolution + 1)
    zs = np.linspace(lo[1], hi[1], resolution + 1)
    x, z = np.meshgrid(xs, zs, indexing="ij")
    y = np.asarray(terrain.height(x, z), np.float64)
    points = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(resolution), np.arange(resolution), indexing="ij")
    v0 = (i * (resolution + 1) + j).ravel()
    # counter-clockwise seen from above (+y), so normals point up
    quads = np.stack([v0, v0 + 1, v0 + resolution + 2, v0 + resolution + 1], axis=-1)
    return points, quads


def terrain_bounds(record: dict, extent: float | None):
    """x/z square the mesh covers: the bodies' whole range plus 5 m, or +-extent about its centre."""
    xz = record["position"][..., [0, 2]].reshape(-1, 2)
    finite = xz[np.all(np.isfinite(xz), axis=1)]
    lo, hi = (finite.min(axis=0), finite.max(axis=0)) if len(finite) else (np.zeros(2), np.zeros(2))
    if extent is not None:
        centre = (lo + hi) / 2
        return centre - extent, centre + extent
    return lo - 5.0, hi + 5.0


def export_usd(record: dict, path, extent: float | None = None, resolution: int = 128):
    """Write the run as a USD stage (see the module docstring for the layout)."""
    try:
        from pxr import Gf, Usd, UsdGeom, Vt
    except ImportError:
        raise ValueError("--usd needs the USD Python modules: pip install usd-core "
                         "(or pip install \"warp-sim[usd]\")") from None
    pos = np.asarray(record["position"], np.float64)
    quat = np.asarray(record["orientation"], np.float64)
    times = np.asarray(record["time"], np.float64)
    shape, size = np.asarray(record["shape"]), np.asarray(record["size"], np.float64)
    f, n = pos.shape[:2]

    path = Path(path)
    if path.exists():
        path.unlink()  # CreateNew refuses to overwrite
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(max(f - 1, 0))
    span = times[-1] - times[0]
    stage.SetTimeCodesPerSecond((f - 1) / span if f > 1 and span > 0 else 24.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    summary = record.get("summary") or {}
    if isinstance(summary, dict) and summary.get("scene"):
        world.GetPrim().SetCustomDataByKey("warp_sim:scene", str(summary["scene"]))
    metadata = record.get("metadata")
    if isinstance(metadata, dict) and metadata:  # where the run came from: scene text, versions, machine
        world.GetPrim().SetCustomDataByKey("warp_sim:metadata", json.dumps(metadata, default=str))

    terrain = terrain_from_record(record)
    if isinstance(terrain, FourierTerrain) or (isinstance(terrain, PlaneTerrain) and abs(terrain.normal[1]) > 1e-6):
        lo, hi = terrain_bounds(record, extent)
        points, quads = terrain_grid(terrain, lo, hi, resolution)
        mesh = UsdGeom.Mesh.Define(stage, "/World/Terrain")
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(quads), 4, np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(quads.ravel().astype(np.int32)))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateExtentAttr([Gf.Vec3f(*points.min(axis=0)), Gf.Vec3f(*points.max(axis=0))])
        mesh.CreateDisplayColorAttr([Gf.Vec3f(0.35, 0.55, 0.3)])

    UsdGeom.Scope.Define(stage, "/World/Bodies")
    sphere_colour, box_colour = Gf.Vec3f(0.9, 0.45, 0.15), Gf.Vec3f(0.25, 0.5, 0.9)
    for b in range(n):
        prim_path = f"/World/Bodies/body_{b:06d}"
        if shape[b] == SHAPE_SPHERE:
            geom = UsdGeom.Sphere.Define(stage, prim_path)
            geom.CreateRadiusAttr(float(size[b, 0]))
            geom.CreateDisplayColorAttr([sphere_colour])
        else:
            geom = UsdGeom.Cube.Define(stage, prim_path)
            geom.CreateSizeAttr(2.0)
            geom.CreateDisplayColorAttr([box_colour])
        translate = geom.AddTranslateOp()
        orient = geom.AddOrientOp(UsdGeom.XformOp.PrecisionFloat)
        if shape[b] != SHAPE_SPHERE:
            geom.AddScaleOp().Set(Gf.Vec3f(*size[b]))
        t_attr, q_attr = translate.GetAttr(), orient.GetAttr()
        for i in range(f):
            t_attr.Set(Gf.Vec3d(*pos[i, b]), i)
            x, y, z, w = quat[i, b]
            q_attr.Set(Gf.Quatf(float(w), float(x), float(y), float(z)), i)
    stage.GetRootLayer().Save()
    return stage
