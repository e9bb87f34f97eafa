"""``[[volumes]]`` entries of draaw-mi scene files -> Mitsuba shapes and media.

One entry is one voxel grid, rendered as solid voxels or as smoke::

    [[volumes]]
    name = "plume"
    mode = "smoke"                       # "solid" (default) | "smoke"
    procedural = { type = "plume", seed = 3, resolution = [40, 56, 40] }
    # or: file = "grid.npz" | "density.vol" | "mesh.obj" (voxelised);  or inline arrays:
    # density = [[[...]]] / occupied = [[[...]]]   (nested lists, [ix][iy][iz])
    bounds = [[-1, 0, -1], [1, 2, 1]]    # world box (default: from the file, else the unit cube)
    resolution = 64                      # voxelising a mesh (int or [nx, ny, nz])
    fill = "surface"                     # voxelising a mesh: "surface" | "solid"
    # smoke keys
    density_scale = 8.0                  # sigma_t = density_scale * density  (1/world units)
    albedo = [0.9, 0.9, 0.9]             # constant smoke colour (default: the grid's)
    g = 0.3                              # Henyey-Greenstein, |g| <= 0.999
    filter = "trilinear"                 # "nearest" | "trilinear"
    # solid keys
    material = "clay"                    # a [materials] entry of type draaw (colours from voxels)
    color = [0.8, 0.2, 0.1]              # one colour for every voxel (default: the grid's)

Errors are :class:`SceneError` naming ``file: volumes[i].key``. Smoke boxes may touch but not
overlap (:func:`~draaw_mi.scene.smoke_boxes.check_smoke_boxes_disjoint`).
"""
from __future__ import annotations

import os

import numpy as np

from ..errors import DraawError, ParameterError
from ..limits import FLOAT32_MAX, HG_G_MAX, grid_size_problem
from ..media.faces import solid_meshes
from ..media.mitsuba_dicts import FILTERS, smoke_shape
from ..media.procedural import plume
from ..media.volfile import read_vol
from ..media.voxel_grid import VoxelGrid
from .context import safe_id
from .schema import check_keys, number, shown, string, vector

VOLUME_KEYS = ("name", "mode", "file", "procedural", "density", "occupied", "bounds", "resolution", "fill",
               "density_scale", "albedo", "g", "filter", "material", "color", "seed")
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


def _bounds(value, where):
    if not isinstance(value, list) or len(value) != 2:
        raise (where / "bounds").error(f"{value!r} is not [[xmin, ymin, zmin], [xmax, ymax, zmax]]")
    lo = np.array(vector(value[0], where / "bounds" / 0))
    hi = np.array(vector(value[1], where / "bounds" / 1))
    if np.any(hi <= lo):
        raise (where / "bounds").error(f"{value!r} is an empty box; expected min < max on every axis")
    return lo, hi


def _array(value, where, key):
    try:
        arr = np.array(value, dtype=np.float64)
    except (ValueError, TypeError):
        raise (where / key).error("is not a nested list of numbers [ix][iy][iz]") from None
    if arr.ndim != 3 or min(arr.shape) < 1:
        raise (where / key).error(f"has shape {arr.shape}; expected a non-empty [ix][iy][iz] nested list")
    return arr


#: voxels per axis at most; the grid's cells at most limits.MAX_GRID_CELLS (2^26, ~4.5 GB)
MAX_GRID_RESOLUTION = 1024


def _density_vol(path: str, seed: int, box: dict, where):
    """A ``.vol`` file's grid as a volume's density (its header box read only without
    ``bounds``); a file of another channel count is one error in the scene's terms (an entry
    has no ``what``: ``VoxelGrid.from_vol``'s hint does not apply)."""
    try:
        return VoxelGrid.from_vol(path, seed=seed, **box)
    except ParameterError:
        channels = read_vol(path)[0].shape[3]
        if channels == 1:
            raise
    raise (where / "file").error(
        f"{path!r} has {channels} channels; a [[volumes]] .vol file is the density, 1 channel (3 are a "
        "colour grid, as save_vol(what='smoke_color') writes, or an RGB extinction): keep a grid's "
        "density and colours in one .npz (VoxelGrid.save) or write its density with save_vol")


def _grid_resolution(value, where):
    """Voxels per axis: one integer in [1, MAX_GRID_RESOLUTION] for all three, or a list of
    three, making at most :data:`~draaw_mi.limits.MAX_GRID_CELLS` cells."""
    hi = MAX_GRID_RESOLUTION
    if isinstance(value, (list, tuple)):
        if len(value) != 3:
            raise where.error(f"{value!r}; expected an integer or a list of 3 integers (voxels per axis)")
        res = tuple(int(number(v, where / i, lo=1, hi=hi, integer=True)) for i, v in enumerate(value))
    else:
        res = int(number(value, where, lo=1, hi=hi, integer=True))
    too_large = grid_size_problem(res if isinstance(res, tuple) else (res,) * 3)
    if too_large:
        raise where.error(too_large)
    return res


def load_volume_grid(entry: dict, ctx, where) -> VoxelGrid:
    """Build the :class:`VoxelGrid` an entry describes (no Mitsuba objects yet)."""
    sources = [k for k in ("file", "procedural", "density", "occupied") if k in entry]
    if not sources:
        raise where.error("needs a grid: one of 'file', 'procedural', 'density' or 'occupied'")
    if ("file" in sources or "procedural" in sources) and len(sources) > 1:
        raise where.error(f"give one of 'file', 'procedural' or inline arrays, not {' and '.join(sources)}")
    voxelised = "file" in entry and str(entry["file"]).lower().endswith(MESH_SUFFIXES)
    for key in ("resolution", "fill"):
        if key in entry and not voxelised:
            # (refused, not ignored: a grid that is not a voxelised mesh has its own size)
            hint = "; a procedural grid's size is procedural.resolution" if "procedural" in entry else ""
            raise (where / key).error(f"'{key}' sets how a mesh 'file' is voxelised; this volume has "
                                      f"no mesh file{hint}")
    seed = int(number(entry.get("seed", 0), where / "seed", lo=0, integer=True))
    bounds = _bounds(entry["bounds"], where) if "bounds" in entry else None
    kw = {} if bounds is None else {"bbox_min": bounds[0], "bbox_max": bounds[1]}
    try:
        if "file" in entry:
            path = ctx.path(string(entry["file"], where / "file"))
            if not os.path.isfile(path):
                raise (where / "file").error(f"{path!r} does not exist")
            low = path.lower()
            if low.endswith(".npz"):
                g = VoxelGrid.load(path, seed=seed)
            elif low.endswith(".vol"):
                g = _density_vol(path, seed, kw, where)
            elif low.endswith(MESH_SUFFIXES):
                res = _grid_resolution(entry.get("resolution", 64), where / "resolution")
                fill = string(entry.get("fill", "surface"), where / "fill", ("surface", "solid"))
                # voxelised in the mesh's own box and then placed at 'bounds', as every other
                # source is (a world box used as the voxelisation window in the mesh's coordinates
                # would crop the mesh to a piece, or to nothing, without a word)
                g = VoxelGrid.from_mesh(path, res, fill, seed=seed)
            else:
                raise (where / "file").error(f"{path!r}: unknown grid format; expected .npz, .vol or a mesh "
                                             f"({', '.join(MESH_SUFFIXES)})")
            if bounds is not None:
                g.bbox_min, g.bbox_max = bounds
        elif "procedural" in entry:
            p = entry["procedural"]
            if not isinstance(p, dict) or p.get("type") != "plume":
                raise (where / "procedural").error(f"{p!r}; expected a table with type = 'plume'")
            extra = set(p) - {"type", "seed", "resolution"}
            if extra:
                raise (where / "procedural").error(f"unknown key {sorted(extra)[0]!r}; valid: type, seed, resolution")
            dens = plume(_grid_resolution(p.get("resolution", [48, 64, 48]), where / "procedural" / "resolution"),
                         seed=int(number(p.get("seed", 0), where / "procedural" / "seed", lo=0, integer=True)))
            g = VoxelGrid.from_arrays(density=dens, seed=seed, **kw)
        else:
            dens = _array(entry["density"], where, "density") if "density" in entry else None
            occ = _array(entry["occupied"], where, "occupied") != 0 if "occupied" in entry else None
            g = VoxelGrid.from_arrays(occupied=occ, density=dens, seed=seed, **kw)
    except ParameterError as e:
        raise where.error(str(e)) from None
    return g


def volume_dicts(entry: dict, index: int, raw_materials: dict, ctx, where) -> tuple[dict, dict]:
    """``({id: mitsuba dict or object}, info)`` for one ``[[volumes]]`` entry."""
    check_keys(entry, VOLUME_KEYS, where)
    name = safe_id(string(entry.get("name", f"volume_{index}"), where / "name"))
    mode = string(entry.get("mode", "solid"), where / "mode", ("solid", "smoke"))
    solid_only, smoke_only = ("material", "color"), ("density_scale", "albedo", "g", "filter")
    for k in (smoke_only if mode == "solid" else solid_only):
        if k in entry:
            raise (where / k).error(f"applies to mode = {'smoke' if mode == 'solid' else 'solid'} volumes only")
    grid = load_volume_grid(entry, ctx, where)
    info = {"name": name, "mode": mode, "shape": list(grid.shape),
            "bounds": [grid.bbox_min.tolist(), grid.bbox_max.tolist()]}
    try:
        if mode == "smoke":
            g_phase = number(entry.get("g", 0.0), where / "g")
            if not abs(g_phase) <= HG_G_MAX:
                raise (where / "g").error(f"{g_phase!r}; expected a Henyey-Greenstein g in "
                                          f"[-{HG_G_MAX}, {HG_G_MAX}]")
            scale = number(entry.get("density_scale", 1.0), where / "density_scale", lo=0)
            filt = string(entry.get("filter", "trilinear"), where / "filter", FILTERS)
            albedo = vector(entry["albedo"], where / "albedo", lo=0) if "albedo" in entry else None
            if albedo is not None and max(albedo) > 1:
                raise (where / "albedo").error(f"{albedo!r} is above 1; expected values in [0, 1]")
            if not np.any(grid.density > 0) and np.any(grid.occupied):
                # a voxelised mesh or an occupancy grid as smoke: density 1 per voxel (times
                # density_scale) and the voxel colours as albedo, as VoxelGrid.to_smoke does
                # (not refused for "no density > 0": such a source has no density)
                grid.to_smoke(1.0)
            if not np.any(grid.density > 0):
                raise (where / "density").error("the grid has no density > 0 and no occupied voxel "
                                                "(nothing to render as smoke)")
            # Mitsuba multiplies in float32: a product beyond its range is Inf, and NaN pixels
            peak = float(grid.density.max()) * scale
            if not peak <= FLOAT32_MAX:
                raise (where / "density_scale").error(
                    f"{scale!r} times the grid's largest density {float(grid.density.max()):g} is "
                    f"{peak:g}, beyond float32 ({FLOAT32_MAX:.3g}); expected a smaller scale")
            info.update(cells=int((grid.density > 0).sum()), max_sigma_t=float(grid.density.max() * scale), g=g_phase)
            return {name: smoke_shape(grid, g_phase=g_phase, scale=scale, filter_type=filt, albedo=albedo)}, info
        mat_params: dict = {}
        if "material" in entry:
            mname = string(entry["material"], where / "material")
            if mname not in raw_materials:
                raise (where / "material").error(f"unknown material {mname!r}")
            table = dict(raw_materials[mname])
            if table.pop("type", "draaw") != "draaw":
                raise (where / "material").error(f"{mname!r} is not a draaw material (needed for voxel colours)")
            table.pop("base_color", None)
            mat_params = table
        if "color" in entry:
            color = vector(entry["color"], where / "color", lo=0)
            if max(color) > 1.0:       # (a solid colour above 1 amplifies light: GO-Draaw's 0-255?)
                raise (where / "color").error(f"{shown(entry['color'])}; expected values in [0, 1] (GO-Draaw's "
                                              "0-255 colours divided by 255)")
            grid.color[:] = color
        if not grid.occupied.any():
            raise where.error("the grid has no solid voxels (mode = 'solid')")
        meshes = solid_meshes(grid, mat_params, name=name)
        info.update(voxels=int(grid.occupied.sum()), faces=int(sum(m.face_count() for m in meshes.values()) // 2))
        return meshes, info
    except ParameterError as e:
        raise where.error(str(e)) from None
    except DraawError:
        raise
