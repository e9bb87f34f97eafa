"""What one scene description's translation shares: its folder, the files it reads, and the
ids it gives Mitsuba objects."""
from __future__ import annotations

import os
import re


class BuildContext:
    """State shared while translating one description (base folder, temp folder, counters)."""
    def __init__(self, base_dir: str, tmp_dir: str, source: str):
        self.base_dir, self.tmp_dir, self.source = base_dir, tmp_dir, source
        self.counter = 0
        self.files: list[str] = []      # every file the scene reads (info["files"])
        self.relative: dict[str, str] = {}   # relative name as written -> the file (info["relative_files"])

    def path(self, p: str) -> str:
        """A file the scene names, resolved against its folder (and remembered)."""
        path = p if os.path.isabs(p) else os.path.normpath(os.path.join(self.base_dir, p))
        if path not in self.files:
            self.files.append(path)
        if not os.path.isabs(p):
            self.relative[p] = path
        return path

    def unique(self, stem: str) -> str:
        self.counter += 1
        return f"{stem}_{self.counter}"


def safe_id(name: str) -> str:
    """A Mitsuba object id from a free-form name ('.' is reserved in parameter paths).

    >>> safe_id("Blue_Light.001")
    'Blue_Light_001'
    """
    return re.sub(r"[^A-Za-z0-9_-]", "_", name)
