"""``VoxelGrid``: occupancy, solid colour, smoke colour and density on a regular grid.

Arrays are numpy, indexed ``[ix, iy, iz]`` (shape ``(nx, ny, nz)``; colours get a trailing
RGB axis); the grid covers the world box ``bbox_min .. bbox_max`` and cells need not be cubic.
Colours are linear RGB in [0, 1] (GO-Draaw keeps 0-255 RGBA; "occupied" there means alpha != 0,
here it is the ``occupied`` mask). Density is the extinction coefficient sigma_t in 1/world
units (>= 0); the smoke colour is the single-scattering albedo.

Editing follows GO-Draaw (``go-draaw-spec.md`` §4.4) with its quirks fixed; each method's
docstring names the quirk it fixes. Random choices use the grid's seeded generator
(``seed=`` at construction, or an explicit ``rng=``), so edits are reproducible.

Example::

    >>> import numpy as np
    >>> from draaw_mi.media import VoxelGrid
    >>> g = VoxelGrid.empty((4, 4, 4), bbox_min=(0, 0, 0), bbox_max=(1, 1, 1), seed=1)
    >>> g.draw((1, 2, 3), color=(1, 0, 0))
    (1, 2, 3)
    >>> int(g.occupied.sum()), g.pick((-1, 0.6, 0.9), (1, 0, 0))
    (1, (1, 2, 3))
"""
from __future__ import annotations

import copy
import os

import mitsuba as mi
import numpy as np

from ..errors import IOFailure, ParameterError
from ..io import atomic_path
from ..limits import FLOAT32_MAX, grid_size_problem
from .grid_checks import check_density
from .grid_checks import resolution as _resolution
from .pick import traverse
from .volfile import read_vol, vol_box, write_vol
from .voxelize import load_triangles, voxelize

Index = tuple[int, int, int]


def _color(value, where: str) -> np.ndarray:
    c = np.asarray(value, dtype=np.float64).reshape(-1)
    if c.size == 1:
        c = np.repeat(c, 3)
    if c.size != 3 or not np.all(np.isfinite(c)) or np.any(c < 0) or np.any(c > 1):
        # (a colour above 1 is refused, not clipped)
        raise ParameterError(f"{where}: colour {value!r}; expected 3 values in [0, 1]")
    return c.astype(np.float32)


class VoxelGrid:
    """A regular voxel grid (see the module docstring).

    ==============  =================  ==========================================================
    attribute       shape / dtype      meaning
    ==============  =================  ==========================================================
    occupied        (nx, ny, nz) bool  solid voxel present
    color           (nx, ny, nz, 3)    solid voxel colour (linear RGB, [0, 1])
    density         (nx, ny, nz)       smoke extinction sigma_t (1/world units, >= 0)
    smoke_color     (nx, ny, nz, 3)    smoke single-scattering albedo ([0, 1])
    bbox_min/max    (3,) float64       world box of the grid
    ==============  =================  ==========================================================
    """
    def __init__(self, occupied, color, density, smoke_color, bbox_min, bbox_max, seed: int | None = 0):
        self.occupied = np.asarray(occupied, dtype=bool)
        self.color = np.asarray(color, dtype=np.float32)
        self.density = np.asarray(density, dtype=np.float32)
        self.smoke_color = np.asarray(smoke_color, dtype=np.float32)
        self.bbox_min = np.asarray(bbox_min, dtype=np.float64).reshape(-1)
        self.bbox_max = np.asarray(bbox_max, dtype=np.float64).reshape(-1)
        self.rng = np.random.default_rng(seed)
        self.validate("VoxelGrid")

    # ------------------------------------------------------------------ construction
    @classmethod
    def empty(cls, resolution, bbox_min=(-0.5, -0.5, -0.5), bbox_max=(0.5, 0.5, 0.5),
              seed: int | None = 0) -> "VoxelGrid":
        """An empty grid (no voxels, no smoke). ``resolution``: an int or ``(nx, ny, nz)``, at most
        :data:`~draaw_mi.limits.MAX_GRID_CELLS` cells (2^26, ~4.5 GB to voxelise and render)."""
        shape = _resolution(resolution, "VoxelGrid.empty")
        return cls(np.zeros(shape, bool), np.zeros(shape + (3,), np.float32),
                   np.zeros(shape, np.float32), np.full(shape + (3,), 0.8, np.float32),
                   bbox_min, bbox_max, seed)

    @classmethod
    def from_arrays(cls, occupied=None, color=None, density=None, smoke_color=None,
                    bbox_min=(-0.5, -0.5, -0.5), bbox_max=(0.5, 0.5, 0.5), seed: int | None = 0):
        """A grid from any subset of the arrays (the others default to empty / 0.8 grey);
        every given array must have the same ``(nx, ny, nz)``. A colour may be one RGB triple."""
        shape = None
        for name, a in (("occupied", occupied), ("density", density)):
            if a is not None:
                try:
                    s = np.shape(a)
                except ValueError:              # (numpy's 'inhomogeneous shape', unnamed)
                    raise ParameterError(f"VoxelGrid.from_arrays: {name} is a ragged nested list; "
                                         "expected an (nx, ny, nz) array") from None
                if len(s) != 3:
                    raise ParameterError(f"VoxelGrid.from_arrays: {name} has shape {s}; expected (nx, ny, nz)")
                if shape is not None and s != shape:
                    raise ParameterError(f"VoxelGrid.from_arrays: {name} has shape {s}; expected {shape} "
                                         "like the other arrays")
                shape = s
        for name, a in (("color", color), ("smoke_color", smoke_color)):
            if a is not None and np.ndim(a) == 4:
                s = np.shape(a)[:3]
                if shape is not None and s != shape:
                    raise ParameterError(f"VoxelGrid.from_arrays: {name} has shape {np.shape(a)}; "
                                         f"expected {shape + (3,)}")
                shape = s
        if shape is None:
            raise ParameterError("VoxelGrid.from_arrays: give at least one of occupied, density or a "
                                 "per-voxel colour array")
        for name, a in (("occupied", occupied), ("color", color), ("density", density),
                        ("smoke_color", smoke_color)):
            if a is not None and np.iscomplexobj(a):
                # (numpy would drop the imaginary part with only a ComplexWarning)
                raise ParameterError(f"VoxelGrid.from_arrays: {name} is complex; expected real values")
        problem = grid_size_problem(shape)
        if problem:
            raise ParameterError(f"VoxelGrid.from_arrays: arrays of shape {problem}")
        g = cls.empty(shape, bbox_min, bbox_max, seed)
        if occupied is not None:
            g.occupied = np.asarray(occupied, bool).copy()
        if density is not None:
            # checked in float64 first: a cast would turn 1e39 into inf (an overflow warning)
            d64 = np.asarray(density, np.float64)
            check_density(d64, "VoxelGrid.from_arrays")
            g.density = d64.astype(np.float32)
        for name, a in (("color", color), ("smoke_color", smoke_color)):
            if a is None:
                continue
            arr = np.asarray(a, np.float32)
            if arr.ndim != 4:
                arr = np.broadcast_to(_color(arr, f"VoxelGrid.from_arrays: {name}"), shape + (3,))
            setattr(g, name, np.array(arr, np.float32))
        if color is None and occupied is not None:
            g.color[:] = 0.8
        g.validate("VoxelGrid.from_arrays")
        return g

    @classmethod
    def from_mesh(cls, mesh, resolution=96, fill: str = "surface", bbox_min=None, bbox_max=None,
                  color=(0.8, 0.8, 0.8), seed: int | None = 0) -> "VoxelGrid":
        """Voxelise a mesh (a file path or a ``trimesh.Trimesh``); see
        :func:`draaw_mi.media.voxelize.voxelize`. Default box: the mesh's bounding box."""
        tris = load_triangles(mesh)
        if bbox_min is None or bbox_max is None:
            pts = tris.reshape(-1, 3)
            lo, hi = pts.min(0), pts.max(0)
            pad = 1e-4 * max(float(np.max(hi - lo)), 1e-12)
            bbox_min = lo - pad if bbox_min is None else bbox_min
            bbox_max = hi + pad if bbox_max is None else bbox_max
        g = cls.empty(resolution, bbox_min, bbox_max, seed)
        name = repr(os.fspath(mesh)) if isinstance(mesh, (str, os.PathLike)) else f"the {type(mesh).__name__}"
        g.occupied = voxelize(tris, g.shape, g.bbox_min, g.bbox_max, fill,
                               name=f"VoxelGrid.from_mesh: mesh {name}")
        g.color[g.occupied] = _color(color, "VoxelGrid.from_mesh")
        return g

    @classmethod
    def go_draaw(cls, mesh_path: str, scale: float = 75.0, resolution: int = 96,
                 seed: int | None = 0) -> "VoxelGrid":
        """GO-Draaw's start-up grid (``go-draaw-spec.md`` §4.1): the mesh scaled by ``scale``
        (GO-Draaw loads scenes x75), box = the object box x0.75 *about the world origin*
        (the object box starts as the zero box, so it always holds the origin: §2.1's quirk,
        kept, as it sets the cells' size), ``resolution ** 3`` cells, each triangle voxelised, filled cells with a random colour,
        smoke colour (0, 0, 0) and density 0.001 everywhere.

        Fixed quirks: GO-Draaw stores the per-cell centre positions transposed (x<->z), which only
        affects its baked light map (not built here); the surface test uses the
        distance to the triangle rather than to its plane plus a barycentric test, which
        leaves holes along the edges of thin triangles (see :func:`~draaw_mi.media.voxelize.voxelize`).
        """
        tris = load_triangles(mesh_path) * float(scale)
        pts = tris.reshape(-1, 3)
        lo, hi = np.minimum(pts.min(0), 0.0) * 0.75, np.maximum(pts.max(0), 0.0) * 0.75
        g = cls.empty(resolution, lo, hi, seed)
        g.occupied = voxelize(tris, g.shape, g.bbox_min, g.bbox_max, "surface")
        n = int(g.occupied.sum())
        g.color[g.occupied] = g.rng.random((n, 3), dtype=np.float32)
        g.smoke_color[:] = 0.0
        g.density[:] = 0.001
        return g

    # ------------------------------------------------------------------ properties
    @property
    def shape(self) -> Index:
        return tuple(int(s) for s in self.occupied.shape)

    @property
    def cell_size(self) -> np.ndarray:
        return (self.bbox_max - self.bbox_min) / np.asarray(self.shape)

    def centers(self) -> np.ndarray:
        """World positions of every cell centre, shape (nx, ny, nz, 3)."""
        axes = [self.bbox_min[a] + (np.arange(n) + 0.5) * self.cell_size[a] for a, n in enumerate(self.shape)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    def copy(self) -> "VoxelGrid":
        """An independent copy, its generator's state included: the copy's random edits repeat
        the original's, and copying leaves the original's stream as it was."""
        g = VoxelGrid(self.occupied.copy(), self.color.copy(), self.density.copy(),
                      self.smoke_color.copy(), self.bbox_min.copy(), self.bbox_max.copy())
        g.rng = copy.deepcopy(self.rng)
        return g

    def __repr__(self) -> str:
        return (f"VoxelGrid(shape={self.shape}, voxels={int(self.occupied.sum())}, "
                f"smoke_cells={int((self.density > 0).sum())}, box={self.bbox_min.tolist()}.."
                f"{self.bbox_max.tolist()})")

    def validate(self, where: str = "VoxelGrid") -> None:
        """Check shapes, bounds and values; raise :class:`ParameterError` naming the field."""
        shape = self.occupied.shape
        if self.occupied.ndim != 3 or min(shape) < 1:
            raise ParameterError(f"{where}: occupied has shape {shape}; expected (nx, ny, nz) with sizes >= 1")
        for name in ("density",):
            a = getattr(self, name)
            if a.shape != shape:
                raise ParameterError(f"{where}: {name} has shape {a.shape}; expected {shape}")
        for name in ("color", "smoke_color"):
            a = getattr(self, name)
            if a.shape != shape + (3,):
                raise ParameterError(f"{where}: {name} has shape {a.shape}; expected {shape + (3,)}")
            if not np.all(np.isfinite(a)) or np.any(a < 0) or np.any(a > 1):
                # (above 1, a solid colour would amplify light and a smoke albedo be clipped unsaid)
                raise ParameterError(f"{where}: {name} has values outside [0, 1] or non-finite ones; "
                                     "expected colours in [0, 1]")
        check_density(self.density, where)
        lo, hi = self.bbox_min, self.bbox_max
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)):
            raise ParameterError(f"{where}: bounds {lo.tolist()}..{hi.tolist()}; expected two finite 3-vectors")
        if np.any(hi <= lo):
            raise ParameterError(f"{where}: bounds {lo.tolist()}..{hi.tolist()} are empty; expected "
                                 "bbox_min < bbox_max on every axis")

    # ------------------------------------------------------------------ lookup and picking
    def index_of(self, p) -> Index | None:
        """Cell containing world point ``p`` (the max face belongs to the last cell), or None."""
        p = np.asarray(p, float)
        rel = (p - self.bbox_min) / self.cell_size
        # (a NaN coordinate would pass both tests: index -9223372036854775808)
        if not np.all(np.isfinite(p)) or np.any(rel < 0) or np.any(p > self.bbox_max):
            return None
        i = np.minimum(np.floor(rel).astype(int), np.asarray(self.shape) - 1)
        return int(i[0]), int(i[1]), int(i[2])

    def pick(self, origin, direction) -> Index | None:
        """First occupied cell along the ray ``origin + t direction`` (t >= 0), or None.

        Exact: a DDA visits every cell the ray crosses (fixes GO-Draaw's 64 fixed steps, which
        skip thin features and can pick a cell behind the visible one)."""
        d = np.asarray(direction, float)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.any(d != 0):
            raise ParameterError(f"VoxelGrid.pick: direction {direction!r}; expected a finite non-zero vector")
        o = np.asarray(origin, float)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise ParameterError(f"VoxelGrid.pick: origin {origin!r}; expected a finite 3-vector")
        for cell, _, _ in traverse(o, d, self.bbox_min, self.bbox_max, self.shape):
            if self.occupied[cell]:
                return cell
        return None

    def pick_pixel(self, sensor, x: float, y: float) -> Index | None:
        """First occupied cell under pixel ``(x, y)`` (pixel centre at ``+0.5``) of a Mitsuba
        sensor (or a scene / :class:`~draaw_mi.scene.DraawScene`, whose first sensor is used)."""
        if hasattr(sensor, "mi_scene"):                 # a DraawScene (not imported: a layer above)
            sensor = sensor.mi_scene
        if isinstance(sensor, mi.Scene):
            sensor = sensor.sensors()[0]
        w, h = sensor.film().crop_size()
        if not (0 <= x < w and 0 <= y < h):
            raise ParameterError(f"VoxelGrid.pick_pixel: pixel ({x}, {y}) is outside the {w}x{h} film")
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((x + 0.5) / w, (y + 0.5) / h), mi.Point2f(0.5))
        o = np.array([ray.o.x[0], ray.o.y[0], ray.o.z[0]])
        d = np.array([ray.d.x[0], ray.d.y[0], ray.d.z[0]])
        return self.pick(o, d)

    def _target(self, at, what: str) -> Index | None:
        """``at`` is a cell index ``(ix, iy, iz)`` or a ray ``(origin, direction)``."""
        if at is None:
            return None
        try:
            a = np.asarray(at, dtype=float)
        except (TypeError, ValueError):
            a = np.empty(0)
        if a.shape in ((3,), (2, 3)) and not np.all(np.isfinite(a)):    # (int(nan) is a bare ValueError)
            raise ParameterError(f"VoxelGrid.{what}: at={at!r}; expected finite numbers")
        if a.shape == (3,):
            i = tuple(int(v) for v in a)
            if any(v != int(v) for v in a) or not all(0 <= i[k] < self.shape[k] for k in range(3)):
                raise ParameterError(f"VoxelGrid.{what}: index {at!r} is outside the grid {self.shape}")
            return i
        if a.shape == (2, 3):
            return self.pick(a[0], a[1])
        raise ParameterError(f"VoxelGrid.{what}: at={at!r}; expected a cell index (ix, iy, iz) or a "
                             "ray (origin, direction)")

    # ------------------------------------------------------------------ editing
    def _noisy(self, color, randomness: float, rng, n: int, where: str) -> np.ndarray:
        c = _color(color, where)
        if randomness < 0 or not np.isfinite(randomness):
            raise ParameterError(f"{where}: randomness={randomness!r}; expected a finite value >= 0")
        out = np.broadcast_to(c, (n, 3)).astype(np.float32)
        if randomness > 0:
            rng = self.rng if rng is None else rng
            out = out + ((rng.random((n, 3)) - 0.5) * randomness).astype(np.float32)
        return np.clip(out, 0.0, 1.0)

    def draw(self, at, color, randomness: float = 0.0, rng=None) -> Index | None:
        """Set the colour of the cell ``at`` (an index, or the first occupied cell along a ray
        ``(origin, direction)``). Returns the cell edited, or None on a miss.

        Fixed quirk: GO-Draaw's paint randomness ``(U() - 1) m`` only ever darkens RGB and
        raises alpha; here the noise is ``(U() - 0.5) m`` per channel, clipped to [0, 1]."""
        i = self._target(at, "draw")
        if i is not None:
            self.color[i] = self._noisy(color, randomness, rng, 1, "VoxelGrid.draw")[0]
            self.occupied[i] = True
        return i

    def erase(self, at) -> Index | None:
        """Remove the solid voxel at ``at`` (index or ray); returns the cell, or None."""
        i = self._target(at, "erase")
        if i is not None:
            self.occupied[i] = False
            self.color[i] = 0.0
        return i

    def add(self, at, color, randomness: float = 0.0, rng=None) -> Index | None:
        """Fill the 3x3x3 block around ``at`` (index or ray) with ``color``; returns the centre.

        Fixed quirk: GO-Draaw offsets the linear index, so the brush wraps across row ends
        (and the grid's faces); here the block is clipped at the grid's faces."""
        i = self._target(at, "add")
        if i is None:
            return None
        sl = tuple(slice(max(0, i[a] - 1), min(self.shape[a], i[a] + 2)) for a in range(3))
        n = int(np.prod([s.stop - s.start for s in sl]))
        cols = self._noisy(color, randomness, rng, n, "VoxelGrid.add")
        self.color[sl] = cols.reshape(self.occupied[sl].shape + (3,))
        self.occupied[sl] = True
        return i

    def paint(self, color, randomness: float = 0.0, rng=None) -> int:
        """Recolour every existing voxel (independent noise per voxel); returns the count.

        Fixed quirk: GO-Draaw counts a voxel as existing only if some RGB > 25 and alpha >
        128, so dark voxels are never repainted; here every occupied voxel is."""
        n = int(self.occupied.sum())
        self.color[self.occupied] = self._noisy(color, randomness, rng, n, "VoxelGrid.paint")
        return n

    def overwrite(self, color, randomness: float = 0.0, rng=None) -> int:
        """Fill the whole box with voxels of ``color`` (GO-Draaw's ``overWriteVoxel``)."""
        n = int(np.prod(self.shape))
        self.color[:] = self._noisy(color, randomness, rng, n, "VoxelGrid.overwrite").reshape(self.color.shape)
        self.occupied[:] = True
        return n

    def set_smoke_color(self, color, randomness: float = 0.0, rng=None) -> None:
        """Set every cell's smoke colour, with per-channel noise ``(U() - 0.5) randomness``.

        Fixed quirk: GO-Draaw adds the noise when ``density > 0`` instead of when
        ``randomness > 0``."""
        n = int(np.prod(self.shape))
        self.smoke_color[:] = self._noisy(color, randomness, rng, n,
                                          "VoxelGrid.set_smoke_color").reshape(self.smoke_color.shape)

    def to_smoke(self, density: float = 1.0, keep_solid: bool = False) -> int:
        """Turn solid voxels into smoke: their colour becomes the smoke colour and their
        density ``density``; the voxels are removed unless ``keep_solid``. Returns the count.

        Fixed quirks: GO-Draaw copies colours of cells with alpha > 10 but keeps one global
        density (the medium stays homogeneous); here the density is per cell."""
        if isinstance(density, bool) or not isinstance(density, (int, float, np.integer, np.floating)):
            raise ParameterError(f"VoxelGrid.to_smoke: density={density!r}; expected a number")
        density = float(density)
        # (finite where it is stored: in float32, 1e39 is Inf)
        if not 0 <= density <= FLOAT32_MAX:
            raise ParameterError(f"VoxelGrid.to_smoke: density={density!r}; expected a value >= 0 "
                                 "and finite in float32")
        m = self.occupied
        self.smoke_color[m] = np.clip(self.color[m], 0.0, 1.0)
        self.density[m] = density
        n = int(m.sum())
        if not keep_solid:
            self.occupied = np.zeros_like(m)
            self.color[m] = 0.0
        return n

    # ------------------------------------------------------------------ files
    def save(self, path: str) -> None:
        """Write the grid to a compressed ``.npz`` (atomically: a crash leaves the old file)."""
        path = os.fspath(path)
        if not path.lower().endswith(".npz"):
            raise ParameterError(f"VoxelGrid.save({path!r}): expected a .npz file name "
                                 "(save_vol writes Mitsuba .vol grids)")
        with atomic_path(path, ".npz") as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, occupied=self.occupied, color=self.color, density=self.density,
                                    smoke_color=self.smoke_color, bbox_min=self.bbox_min,
                                    bbox_max=self.bbox_max, format=np.array("draaw-mi-voxels-1"))

    @classmethod
    def load(cls, path: str, seed: int | None = 0) -> "VoxelGrid":
        """Read a grid written by :meth:`save` (missing arrays take their defaults)."""
        path = os.fspath(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except OSError as e:
            raise IOFailure(f"VoxelGrid.load({path!r}): {e.strerror or e}") from None
        except (ValueError, EOFError) as e:
            with open(path, "rb") as f:
                head = f.read(4)
            if head[:3] == b"VOL":
                raise IOFailure(f"VoxelGrid.load({path!r}): a Mitsuba .vol grid, not a .npz; read it with "
                                "VoxelGrid.from_vol") from None
            if head != b"PK\x03\x04":
                raise IOFailure(f"VoxelGrid.load({path!r}): not a .npz file (no zip archive's header); "
                                "expected a grid written by VoxelGrid.save") from None
            raise IOFailure(f"VoxelGrid.load({path!r}): not a readable .npz file ({e})") from None
        kw = {k: data[k] for k in ("occupied", "color", "density", "smoke_color") if k in data}
        if "bbox_min" in data:
            kw["bbox_min"] = data["bbox_min"]
        if "bbox_max" in data:
            kw["bbox_max"] = data["bbox_max"]
        try:
            return cls.from_arrays(seed=seed, **kw)
        except ParameterError as e:
            raise ParameterError(f"VoxelGrid.load({path!r}): {e}") from None

    @classmethod
    def from_vol(cls, path: str, seed: int | None = 0, *, what: str = "density", bbox_min=None,
                 bbox_max=None) -> "VoxelGrid":
        """Import a grid from Mitsuba's ``.vol`` format: a 1-channel file as the density
        (``what="density"``) or a 3-channel one as the smoke colour (``what="smoke_color"``,
        the density then 0), as :meth:`save_vol` writes them; a file of another channel count
        is refused, naming what it holds. The world box is ``bbox_min .. bbox_max`` where given
        (the header's box is then not read: Mitsuba ignores it, and may have left it empty),
        else the header's."""
        path = os.fspath(path)
        if what not in ("density", "smoke_color"):
            raise ParameterError(f"VoxelGrid.from_vol({path!r}): what={what!r}; expected 'density' or "
                                 "'smoke_color'")
        data, lo, hi = read_vol(path)
        ch = data.shape[3]
        want = 1 if what == "density" else 3
        if ch != want:
            kind = {1: "a density grid", 3: "a colour grid, as save_vol(what='smoke_color') writes"}.get(
                ch, "neither a density nor a colour grid")
            hint = {1: "; read it with what='density'", 3: "; read it with what='smoke_color'"}.get(ch, "")
            raise ParameterError(f"VoxelGrid.from_vol({path!r}): the file has {ch} channels ({kind}); "
                                 f"what={what!r} reads {want}{hint}")
        arr = data.transpose(2, 1, 0, 3)                       # (Z, Y, X, C) -> [ix, iy, iz, c]
        kw = {"density": arr[..., 0]} if what == "density" else {"smoke_color": arr}
        lo, hi = vol_box(path, lo, hi, bbox_min, bbox_max)
        try:
            return cls.from_arrays(bbox_min=lo, bbox_max=hi, seed=seed, **kw)
        except ParameterError as e:
            raise ParameterError(f"VoxelGrid.from_vol({path!r}): {e}") from None

    def save_vol(self, path: str, what: str = "density") -> None:
        """Write ``density`` (1 channel) or ``smoke_color`` (3 channels) as a Mitsuba ``.vol``."""
        path = os.fspath(path)
        if not path.lower().endswith(".vol"):
            raise ParameterError(f"VoxelGrid.save_vol({path!r}): expected a .vol file name "
                                 "(save writes .npz grids)")
        if what == "density":
            arr = self.density[..., None]
        elif what == "smoke_color":
            arr = self.smoke_color
        else:
            raise ParameterError(f"VoxelGrid.save_vol: what={what!r}; expected 'density' or 'smoke_color'")
        write_vol(path, np.ascontiguousarray(arr.transpose(2, 1, 0, 3)), self.bbox_min, self.bbox_max)

