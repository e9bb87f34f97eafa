"""Render the gallery of the sample scenes: ``docs/_static/gallery/<scene>.png`` for every scene
in ``scenes/*.toml`` (batch manifests are not scenes and are left out) and the page that shows
them, ``docs/gallery.md``. Both are committed; the docs build does not render.

Refresh them after a scene or the renderer changes (about a minute on two cores)::

    flock /tmp/draaw-heavy.lock .venv/bin/python docs/make_gallery.py

Each image is the scene as its file sets it (version, depth, post chain), at a small size
(``--size``, the longer side, default 192 pixels) and ``--spp`` samples per pixel (default 256),
seed 0, denoised with Intel OIDN as ``draaw-mi render --denoise`` does (``--raw``: not).
"""
from __future__ import annotations

import argparse
import glob
import os
import sys
import time

import tomllib

DOCS = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(DOCS)
OUT = os.path.join(DOCS, "_static", "gallery")
PAGE = os.path.join(DOCS, "gallery.md")


def scene_files() -> list[str]:
    """The sample scenes: ``scenes/*.toml`` less batch manifests (a top-level ``jobs`` list)."""
    files = []
    for path in sorted(glob.glob(os.path.join(ROOT, "scenes", "*.toml"))):
        with open(path, "rb") as fh:
            if "jobs" not in tomllib.load(fh):
                files.append(path)
    return files


def summary(path: str) -> str:
    """The first sentence of the scene file's opening comment (what it shows), without the
    ``#``s: its lines joined up to the first full stop (a first line alone had been cut
    mid-sentence).

    >>> import tempfile, os
    >>> with tempfile.TemporaryDirectory() as d:
    ...     f = os.path.join(d, "s.toml")
    ...     _ = open(f, "w").write("# A ball (radius 0.5)\\n# on a tile. More.\\n[render]\\n")
    ...     summary(f)
    'A ball (radius 0.5) on a tile.'
    """
    words = []
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            text = line.lstrip("#").strip() if line.startswith("#") else line.strip() or None
            if text is None or not line.startswith("#"):
                if words or text is not None:       # (blank lines before the comment: skipped)
                    break
            elif not text:
                if words:                           # (an empty comment line ends the paragraph)
                    break
            elif not text.startswith("draaw-mi "):
                words.append(text)
    joined = " ".join(words)
    end = joined.find(". ")
    return joined if end < 0 else joined[:end + 1]


def small_resolution(resolution, size: int) -> tuple[int, int]:
    """``resolution`` (W, H) scaled so that its longer side is ``size``, aspect kept.

    >>> small_resolution([320, 180], 192), small_resolution([256, 256], 192)
    ((192, 108), (192, 192))
    """
    w, h = resolution
    k = size / max(w, h)
    return max(1, round(w * k)), max(1, round(h * k))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Render the docs' gallery of scenes/*.toml.")
    p.add_argument("--size", type=int, default=192, help="longer image side in pixels (default 192)")
    p.add_argument("--spp", type=int, default=256, help="samples per pixel (default 256)")
    p.add_argument("--raw", action="store_true", help="do not denoise (default: denoise, as --denoise)")
    args = p.parse_args(argv)
    if args.size < 16 or args.spp < 1:
        raise SystemExit(f"make_gallery: --size {args.size} / --spp {args.spp}; expected size >= 16, spp >= 1")
    import draaw_mi  # here: --help answers without loading Mitsuba

    os.makedirs(OUT, exist_ok=True)
    entries = []
    for path in scene_files():
        name = os.path.splitext(os.path.basename(path))[0]
        scene = draaw_mi.load_scene(path)
        res = small_resolution(scene.resolution, args.size)
        scene = draaw_mi.load_scene(path, resolution=res)
        t0 = time.perf_counter()
        img = draaw_mi.render(scene, spp=args.spp, seed=0, denoise=not args.raw)
        seconds = time.perf_counter() - t0
        draaw_mi.write_png(os.path.join(OUT, f"{name}.png"), img)
        version = scene.settings.get("version", "v4")
        print(f"{name}: {res[0]}x{res[1]}, {args.spp} spp, {version}, {seconds:.1f} s")
        entries.append((name, summary(path), res, version))
        del scene

    write_page(entries, args.spp, args.raw)
    print(f"wrote {PAGE} and {len(entries)} images in {OUT}")
    return 0


def write_page(entries, spp: int, raw: bool) -> None:
    """Write ``gallery.md``: for each ``(name, summary, (w, h), version)`` its image and the
    command that renders it (the image's size, samples and seed)."""
    lines = ["# Gallery of the sample scenes", "",
             "The scenes of `scenes/`, each rendered as its file sets it (render version, depth, post",
             f"chain) at a small size, {spp} samples per pixel, seed 0"
             + ("." if raw else ", denoised with Intel OIDN (`--denoise`: albedo and normal guides, "
                "the lights seen directly added undenoised; a denoised image is biased)."),
             "The images are stored in `docs/_static/gallery/`; `docs/make_gallery.py` renders them and",
             "writes this page. Each command renders the image above it; without `--resolution`,",
             "`--spp` and `--seed` it renders the scene at its own size and sample count.", ""]
    flag = "" if raw else " --denoise"
    for name, text, res, version in entries:
        lines += [f"## `scenes/{name}.toml`", ""]
        if text:
            lines += [text, ""]
        lines += ["```{image} _static/gallery/" + name + ".png",
                  f":alt: scenes/{name}.toml rendered at {res[0]}x{res[1]}",
                  "```", "",
                  "```sh",
                  f"draaw-mi render scenes/{name}.toml -o out/{name}.exr --png out/{name}.png "
                  f"--resolution {res[0]}x{res[1]} --spp {spp} --seed 0{flag}",
                  "```", ""]
    with open(PAGE, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines).rstrip() + "\n")


if __name__ == "__main__":
    sys.exit(main())
