"""Find the libLLVM that Dr.Jit will load, before Dr.Jit can abort the process.

Dr.Jit 1.5's LLVM backend needs libLLVM >= 16: with LLVM 14/15 (Debian 12's defaults) it
aborts the whole interpreter ("Cannot select ... fminimum") at the first kernel launch. This
module only inspects the file system, so it is safe to run before ``import drjit``. It is
also a small script used by the Makefile::

    python3 draaw_mi/_llvm.py            # exit 0 if a usable libLLVM exists, else 1
    python3 draaw_mi/_llvm.py --install  # as root on Debian: apt-get install libllvm19 if needed
"""
from __future__ import annotations

import glob
import os
import re
import subprocess
import sys

MIN_LLVM = 16
_APT_PACKAGE = "libllvm19"
_SEARCH_DIRS = [
    "/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib",
    "/usr/local/lib", "/opt/homebrew/opt/llvm/lib", "/usr/local/opt/llvm/lib",
]
# libLLVM-19.so[.1] (Debian), libLLVM.so.18.1 (Fedora, Arch), libLLVM.19.dylib / libLLVM-19.dylib
_NAME_RES = (re.compile(r"^libLLVM-(\d+)(?:\.\d+)*(?:git)?\.(?:so|dylib)"),
             re.compile(r"^libLLVM\.so\.(\d+)\.\d+"),
             re.compile(r"^libLLVM\.(\d+)\.dylib"))


def llvm_major_from_name(path: str) -> int | None:
    """Major version encoded in a libLLVM file name, e.g. ``libLLVM-19.so.1`` -> 19.

    >>> llvm_major_from_name('/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1')
    15
    >>> llvm_major_from_name('libLLVM.so') is None
    True
    """
    name = os.path.basename(path)
    for pattern in _NAME_RES:
        m = pattern.search(name)
        if m:
            return int(m.group(1))
    return None


def find_libllvm() -> list[tuple[int, str]]:
    """All versioned libLLVM libraries on the usual search paths, newest first."""
    dirs = list(_SEARCH_DIRS)
    dirs += [d for d in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if d]
    dirs += sorted(glob.glob("/usr/lib/llvm-*/lib"))
    found: dict[str, tuple[int, str]] = {}
    for d in dirs:
        for p in glob.glob(os.path.join(d, "libLLVM*")):
            major = llvm_major_from_name(p)
            if major is not None:
                found.setdefault(os.path.realpath(p), (major, p))
    return sorted(found.values(), reverse=True)


def check_llvm() -> str | None:
    """Return None if Dr.Jit's LLVM backend can work here, else a one-line explanation."""
    override = os.environ.get("DRJIT_LIBLLVM_PATH")
    if override:
        if not os.path.exists(override):
            return f"DRJIT_LIBLLVM_PATH={override!r} does not exist; point it at libLLVM >= {MIN_LLVM}"
        major = llvm_major_from_name(override)
        if major is not None and major < MIN_LLVM:
            return (f"DRJIT_LIBLLVM_PATH={override!r} is LLVM {major}; Dr.Jit 1.5 needs libLLVM >= "
                    f"{MIN_LLVM} (Debian: apt-get install {_APT_PACKAGE})")
        return None
    libs = find_libllvm()
    if not libs:
        return (f"no libLLVM found; Dr.Jit's LLVM backend needs libLLVM >= {MIN_LLVM}: install it "
                f"(Debian: apt-get install {_APT_PACKAGE}) or set DRJIT_LIBLLVM_PATH")
    if libs[0][0] < MIN_LLVM:
        return (f"only libLLVM {libs[0][0]} found ({libs[0][1]}); Dr.Jit 1.5 aborts with LLVM < "
                f"{MIN_LLVM}: install a newer one (Debian: apt-get install {_APT_PACKAGE}) or set "
                f"DRJIT_LIBLLVM_PATH")
    return None


def _main(argv: list[str]) -> int:
    problem = check_llvm()
    if problem is None:
        return 0
    if "--install" not in argv:
        print(f"draaw-mi: {problem}", file=sys.stderr)
        return 1
    if os.geteuid() != 0 or not os.path.exists("/usr/bin/apt-get"):
        print(f"draaw-mi: {problem} (not root or no apt-get: install it yourself)", file=sys.stderr)
        return 1
    print(f"draaw-mi: installing {_APT_PACKAGE} with apt-get ({problem})", file=sys.stderr)
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    subprocess.run(["apt-get", "update", "-qq"], check=True, env=env)
    subprocess.run(["apt-get", "install", "-y", "-qq", _APT_PACKAGE], check=True, env=env)
    problem = check_llvm()
    if problem:
        print(f"draaw-mi: {problem}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
