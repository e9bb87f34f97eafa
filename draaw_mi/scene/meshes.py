"""Mesh files (OBJ/PLY/GLB/STL/OFF via trimesh) split into per-material parts, and PLY export.

Each part carries its MTL/PBR colour and colour texture, mapped to ``draaw`` parameters:
``Kd`` (or a glTF base colour) -> ``base_color``, ``map_Kd`` -> a ``base_color`` bitmap (sRGB
decoded; a glTF base colour texture times its linear ``baseColorFactor``), glTF
metallic/roughness factors -> ``metallic``/``roughness``. Faces without a
material get GO-Draaw's grey (178/255). Parts are handed to Mitsuba as temporary binary PLY
files so that materials can be referenced by name (keys ``<material>.<param>`` in
``mi.traverse``).
"""
from __future__ import annotations

import json
import logging
import mmap
import os
import warnings
from dataclasses import dataclass, field
from urllib.parse import unquote

import numpy as np

from ..errors import user_stacklevel
from ..io import srgb_decode

GO_DRAAW_GREY = 178.0 / 255.0
MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf", ".stl", ".off")


@dataclass
class MeshPart:
    name: str
    vertices: np.ndarray            # (N, 3) float32
    faces: np.ndarray               # (M, 3) uint32
    uv: np.ndarray | None = None    # (N, 2) float32, OpenGL convention (v up)
    material_name: str | None = None
    material: dict = field(default_factory=dict)   # draaw parameters read from the file


def _invented(mat) -> bool:
    """Whether ``mat`` is the stand-in trimesh makes for a mesh with texture coordinates but
    no material (``empty_material``: no name of its own, a 2x2 image of one colour). GO-Draaw
    shades such meshes grey (go-draaw-spec 2.2); read as a texture, monkey.obj would come out at
    albedo 0.127 instead of 0.698."""
    image = getattr(mat, "image", None)
    if hasattr(mat, "_name") or image is None or getattr(image, "size", None) != (2, 2):
        return False
    px = np.asarray(image).reshape(4, -1)
    return bool(np.all(px == px[0]))


def _material_of(geom) -> tuple[str | None, dict]:
    """(material name, draaw parameters) of a trimesh geometry; a glTF base colour is its factor
    times its decoded texture (the factor applies with a texture too)."""
    visual = getattr(geom, "visual", None)
    mat = getattr(visual, "material", None)
    if mat is not None and _invented(mat):
        return mat.name, {}                   # (its name kept: the material ids stay as they were)
    if mat is None:
        colors = getattr(visual, "face_colors", None) if visual is not None and visual.kind == "face" else None
        if colors is not None and len(colors):
            rgb = np.asarray(colors, float)[:, :3].mean(axis=0) / 255.0
            return None, {"base_color": srgb_decode(rgb).tolist()}
        return None, {}
    out: dict = {}
    name = getattr(mat, "name", None)
    factor = None                              # glTF: base colour = factor x texture
    if hasattr(mat, "baseColorFactor"):        # glTF PBR material
        if mat.baseColorFactor is not None:
            raw = np.asarray(mat.baseColorFactor)       # (trimesh keeps it as uint8 0-255)
            factor = raw[:3].astype(float) / (255.0 if raw.dtype == np.uint8 else 1.0)
            out["base_color"] = factor.tolist()
        if getattr(mat, "metallicFactor", None) is not None:
            out["metallic"] = float(np.clip(mat.metallicFactor, 0, 1))
        if getattr(mat, "roughnessFactor", None) is not None:
            out["roughness"] = float(np.clip(mat.roughnessFactor, 0, 1))
        image = getattr(mat, "baseColorTexture", None)
    else:                                      # OBJ/MTL SimpleMaterial: Kd in [0, 255]
        diffuse = getattr(mat, "diffuse", None)
        if diffuse is not None:
            out["base_color"] = (np.asarray(diffuse, float)[:3] / 255.0).tolist()
        image = getattr(mat, "image", None)
    if image is not None:
        arr = np.asarray(image.convert("RGB"), dtype=np.float32) / 255.0
        out["base_color"] = srgb_decode(arr).astype(np.float32)
        if factor is not None:
            # the factor is linear: it scales the decoded texture (so a white texture tinted by
            # (0.2, 1, 1) renders cyan, not white)
            out["base_color"] = (out["base_color"] * factor.astype(np.float32)).astype(np.float32)
    return name, out


def load_mesh_parts(path: str, where) -> list[MeshPart]:
    """Load a mesh file into per-material parts; raise SceneError on unreadable files."""
    import trimesh  # (0.36 s to import: paid by scenes with meshes only)

    if not os.path.isfile(path):
        raise where.error(f"mesh file {path!r} does not exist")
    if not path.lower().endswith(MESH_SUFFIXES):
        raise where.error(f"{path!r} is not a supported mesh file; expected one of {', '.join(MESH_SUFFIXES)}")
    logging.getLogger("trimesh").setLevel(logging.ERROR)
    try:
        loaded = trimesh.load(path, force="scene", process=False)
    except Exception as e:  # noqa: BLE001 - trimesh raises many kinds of errors on bad files
        raise where.error(f"cannot read mesh {path!r}: {type(e).__name__}: {e}") from None
    kd = _obj_diffuse_colours(path, where) if path.lower().endswith(".obj") else {}
    parts = []
    try:
        items = loaded.dump(concatenate=False) if hasattr(loaded, "dump") else [loaded]
    except Exception as e:  # noqa: BLE001
        raise where.error(f"cannot read mesh {path!r}: {e}") from None
    for i, geom in enumerate(items):
        if not hasattr(geom, "faces") or len(geom.faces) == 0:
            continue
        verts = np.asarray(geom.vertices, dtype=np.float32)
        faces = np.asarray(geom.faces, dtype=np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(verts):
            raise where.error(f"mesh {path!r} has invalid face indices")
        if not np.all(np.isfinite(verts)):
            raise where.error(f"mesh {path!r} has non-finite vertex coordinates")
        uv = getattr(getattr(geom, "visual", None), "uv", None)
        uv = np.asarray(uv, dtype=np.float32) if uv is not None and len(uv) == len(verts) else None
        mat_name, mat = _material_of(geom)
        if mat_name in kd and isinstance(mat.get("base_color"), list):
            mat["base_color"] = kd[mat_name]         # (trimesh's are rounded to 1/255)
        if "base_color" not in mat:
            mat["base_color"] = [GO_DRAAW_GREY] * 3
        if not isinstance(mat.get("base_color"), list):
            if uv is None:       # a texture without coordinates cannot be mapped
                mat["base_color"] = mat["base_color"].reshape(-1, 3).mean(axis=0).tolist()
        parts.append(MeshPart(name=f"part{i}", vertices=verts, faces=faces.astype(np.uint32), uv=uv,
                              material_name=mat_name, material=mat))
    if not parts:
        raise where.error(f"mesh {path!r} contains no triangles")
    return parts


def _obj_diffuse_colours(path: str, where) -> dict[str, list[float]]:
    """``{material: Kd}`` of an OBJ's material libraries, as the MTL files write them (trimesh
    rounds them to 1/255 and clips them: Kd 0.020 read 0.0196). A ``RuntimeWarning`` names a
    library that is missing (GO-Draaw stops there; its materials render grey 178 here), a
    ``usemtl`` no library defines (grey 178, as in GO-Draaw: a misspelt name, say) and a Kd
    outside [0, 1] (GO-Draaw's emission trick; clipped here).

    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> _ = open(os.path.join(d, "m.obj"), "w").write("mtllib m.mtl\\nusemtl red\\n")
    >>> _ = open(os.path.join(d, "m.mtl"), "w").write("newmtl red\\nKd 0.02 0.5 1\\n")
    >>> _obj_diffuse_colours(os.path.join(d, "m.obj"), "m.obj")
    {'red': [0.02, 0.5, 1.0]}
    """
    kd: dict[str, list[float]] = {}
    defined: set[str] = set()
    for name, mtl in _material_libraries(path):
        if not os.path.isfile(mtl):
            warnings.warn(f"{where}: material library {name!r} not found; "
                          "its materials render grey", RuntimeWarning, stacklevel=user_stacklevel())
            continue
        current = None
        with open(mtl, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                words = line.split()
                if len(words) >= 2 and words[0] == "newmtl":
                    current = line.strip()[len("newmtl"):].strip()
                    defined.add(current)
                elif len(words) == 4 and words[0] == "Kd" and current is not None:
                    try:
                        rgb = [float(w) for w in words[1:]]
                    except ValueError:
                        continue
                    if not all(0.0 <= c <= 1.0 for c in rgb):
                        warnings.warn(f"{where}: {name}: material {current!r} has Kd {' '.join(words[1:])}; "
                                      "expected values in [0, 1] (clipped; light is given off by a "
                                      "light or a shape's emission)", RuntimeWarning, stacklevel=user_stacklevel())
                    kd[current] = [float(np.clip(c, 0.0, 1.0)) for c in rgb]
    # ("(null)": Blender's name for no material)
    undefined = sorted({u.strip() for u in _lines_starting(path, ("usemtl",))} - defined - {"", "(null)"})
    if undefined:
        warnings.warn(f"{where}: usemtl {', '.join(map(repr, undefined[:3]))}"
                      f"{' ...' if len(undefined) > 3 else ''}: no material library defines it; "
                      "it renders grey", RuntimeWarning, stacklevel=user_stacklevel())
    return kd


def write_ply(path: str, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None = None,
              normals: np.ndarray | None = None) -> None:
    """Binary little-endian PLY with positions, optional (u, 1 - v) texture coordinates and
    optional vertex normals (which Mitsuba then uses instead of computing its own)."""
    n, m = len(vertices), len(faces)
    vfields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        vfields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if uv is not None:
        vfields += [("u", "<f4"), ("v", "<f4")]
    vdata = np.empty(n, dtype=vfields)
    vdata["x"], vdata["y"], vdata["z"] = vertices[:, 0], vertices[:, 1], vertices[:, 2]
    if normals is not None:
        vdata["nx"], vdata["ny"], vdata["nz"] = normals[:, 0], normals[:, 1], normals[:, 2]
    if uv is not None:
        vdata["u"], vdata["v"] = uv[:, 0], 1.0 - uv[:, 1]     # OpenGL -> Mitsuba (v down)
    fdata = np.empty(m, dtype=[("n", "u1"), ("i", "<u4", 3)])
    fdata["n"], fdata["i"] = 3, faces
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {n}"]
    header += [f"property float {name}" for name, _ in vfields]
    header += [f"element face {m}", "property list uchar uint vertex_indices", "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(vdata.tobytes())
        f.write(fdata.tobytes())


def bounds(parts: list[MeshPart], transform=None) -> tuple[np.ndarray, np.ndarray]:
    pts = np.concatenate([p.vertices for p in parts]).astype(np.float64)
    if transform is not None:
        pts = pts @ transform[:3, :3].T + transform[:3, 3]
    return pts.min(axis=0), pts.max(axis=0)




def mesh_side_files(path: str) -> list[str]:
    """The files a mesh file reads besides itself: an OBJ's material libraries (``mtllib``)
    and the images they name (``map_Kd`` and the other ``map_*``, ``bump``, ``norm``,
    ``disp``), a ``.gltf``'s external buffers and images. Those that exist, as absolute
    paths; a batch keys its frames by their content too (:mod:`draaw_mi.batch.planner`).

    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> _ = open(os.path.join(d, "m.obj"), "w").write("mtllib m.mtl\\nv 0 0 0\\n")
    >>> _ = open(os.path.join(d, "m.mtl"), "w").write("newmtl a\\nmap_Kd -s 2 2 1 tex.png\\n")
    >>> _ = open(os.path.join(d, "tex.png"), "wb").write(b"")
    >>> [os.path.basename(p) for p in mesh_side_files(os.path.join(d, "m.obj"))]
    ['m.mtl', 'tex.png']
    """
    folder = os.path.dirname(os.path.abspath(path))
    found: list[str] = []

    def add(name: str, base: str) -> str | None:
        p = os.path.normpath(os.path.join(base, name.strip()))
        if os.path.isfile(p) and p not in found:
            found.append(p)
            return p
        return None

    lower = path.lower()
    if lower.endswith(".obj"):
        for name, _ in _material_libraries(path):
            mtl = add(name, folder)
            for image in _lines_starting(mtl, ("map_", "bump", "norm", "disp")) if mtl else ():
                add(image.split()[-1], os.path.dirname(mtl))     # options come first
    elif lower.endswith(".gltf"):
        try:
            with open(path, encoding="utf-8") as fh:
                doc = json.load(fh)
        except (OSError, ValueError):
            return found
        for entry in list(doc.get("buffers", [])) + list(doc.get("images", [])):
            uri = entry.get("uri") if isinstance(entry, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:"):
                add(unquote(uri), folder)
    return found


def _material_libraries(path: str) -> list[tuple[str, str]]:
    """``(name, path)`` of each material library an OBJ's ``mtllib`` lines name (one name with
    spaces, or several names), beside the OBJ; the paths may not exist."""
    folder = os.path.dirname(os.path.abspath(path))
    out = []
    for libs in _lines_starting(path, ("mtllib",)):
        names = [libs] if os.path.isfile(os.path.join(folder, libs)) else libs.split()
        out += [(name, os.path.normpath(os.path.join(folder, name.strip()))) for name in names]
    return out


def _lines_starting(path: str, keywords: tuple) -> list[str]:
    r"""The rest of each line of a text file whose first word starts with one of ``keywords``
    (``\n``, ``\r\n`` or ``\r`` line ends). The file is mapped, not read, and searched for
    each keyword's bytes (a Python loop over a 3-million-line OBJ takes a second a load).

    >>> import os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "m.mtl")
    >>> _ = open(p, "wb").write(b"newmtl a\r\tmap_Kd  -s 1 1 1 a b.png \rKd 1 1 1\r\nnomap_Kd x\n")
    >>> _lines_starting(p, ("map_",))
    ['-s 1 1 1 a b.png']
    """
    out = []
    try:
        with open(path, "rb") as fh:
            if os.fstat(fh.fileno()).st_size == 0:
                return out
            data = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except (OSError, ValueError):
        return out
    with data:
        found = []
        for word in keywords:
            key = word.encode()
            pos = data.find(key)
            while pos != -1:
                start = max(data.rfind(b"\n", 0, pos), data.rfind(b"\r", 0, pos)) + 1
                if not data[start:pos].strip(b" \t"):             # the line's first word
                    ends = [e for e in (data.find(b"\n", pos), data.find(b"\r", pos)) if e != -1]
                    line = data[pos:min(ends) if ends else len(data)]
                    parts = line.split(None, 1)
                    if len(parts) == 2 and parts[1].strip():
                        found.append((pos, parts[1].strip().decode("utf-8", "replace")))
                pos = data.find(key, pos + 1)
    return [text for _, text in sorted(found)]
