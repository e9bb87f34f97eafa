"""Import-time checks: libLLVM detection and variant selection fail with one clear line."""
from __future__ import annotations

import os
import subprocess
import sys

from draaw_mi._llvm import check_llvm, llvm_major_from_name


def test_llvm_name_parsing():
    assert llvm_major_from_name("/usr/lib/x86_64-linux-gnu/libLLVM-19.so.1") == 19
    assert llvm_major_from_name("libLLVM.so.18.1") == 18
    assert llvm_major_from_name("libLLVM-15.so") == 15
    assert llvm_major_from_name("libfoo.so") is None
    assert llvm_major_from_name("/usr/lib/llvm-19/lib/libLLVM.so.1") is None     # soname only: unknown


def test_this_machine_has_a_usable_llvm():
    assert check_llvm() is None


def _import_in_subprocess(env_extra):
    env = dict(os.environ, **env_extra)
    return subprocess.run([sys.executable, "-c", "import draaw_mi"], capture_output=True, text=True, env=env)


def test_too_old_llvm_override_raises_before_drjit_aborts(tmp_path):
    fake = tmp_path / "libLLVM-15.so.1"
    fake.write_bytes(b"")
    r = _import_in_subprocess({"DRJIT_LIBLLVM_PATH": str(fake)})
    assert r.returncode == 1
    last = r.stderr.strip().splitlines()[-1]
    assert "DraawError" in last and "libllvm19" in last and "LLVM 15" in last


def test_missing_llvm_override_and_bad_variant():
    r = _import_in_subprocess({"DRJIT_LIBLLVM_PATH": "/nonexistent/libLLVM-19.so"})
    assert r.returncode == 1 and "does not exist" in r.stderr.strip().splitlines()[-1]
    r = _import_in_subprocess({"DRAAW_MI_VARIANT": "scalar_rgb"})
    assert r.returncode == 1 and "not supported" in r.stderr.strip().splitlines()[-1]
    r = _import_in_subprocess({"DRAAW_MI_VARIANT": "llvm_ad_rgbx"})
    assert r.returncode == 1 and "is not a Mitsuba variant" in r.stderr.strip().splitlines()[-1]


def test_cli_reports_environment_problems_in_one_line():
    env = dict(os.environ, DRAAW_MI_VARIANT="scalar_rgb")
    exe = os.path.join(os.path.dirname(sys.executable), "draaw-mi")
    cmd = [exe, "info"] if os.path.exists(exe) else [sys.executable, "-m", "draaw_mi_cli", "info"]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    assert r.returncode == 2 and r.stderr.startswith("draaw-mi: error:") and r.stderr.count("\n") == 1


def test_subpackages_are_attributes_after_a_plain_import():
    """``import draaw_mi`` loads none of the batch, bench, CLI and widget code (the scene loader
    needs sdf/ and media/ to read its tables), yet the README's
    ``draaw_mi.sdf.export.to_entries(...)`` and ``draaw_mi.batch.run(...)`` work after it; a
    misspelt name is still an AttributeError. In a fresh interpreter."""
    code = (
        "import sys, draaw_mi\n"
        "assert not {'draaw_mi.batch', 'draaw_mi.bench', 'draaw_mi.cli', 'draaw_mi.widgets'} & set(sys.modules)\n"
        "assert callable(draaw_mi.sdf.export.to_entries) and callable(draaw_mi.sdf.smooth_union)\n"
        "assert callable(draaw_mi.batch.run) and draaw_mi.media.VoxelGrid.__name__ == 'VoxelGrid'\n"
        "for bad in ('draaw_mi.sdf.exprot', 'draaw_mi.batches'):\n"
        "    try:\n"
        "        eval(bad)\n"
        "    except AttributeError as e:\n"
        "        assert repr(bad.rsplit('.', 1)[1]) in str(e), e\n"
        "    else:\n"
        "        raise SystemExit(bad + ' did not raise')\n"
        "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]


def test_a_bare_make_lists_the_targets_and_sets_up_nothing():
    """``make`` with no target ran set-up (which may apt-install libLLVM as root) and ``make help``
    had no rule: now a bare ``make`` is ``make help``, which names every target of the Makefile,
    and each of those is a rule (``make -n``: nothing runs)."""
    import re
    import shutil

    import pytest
    if shutil.which("make") is None:
        pytest.skip("no make on this machine")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

    # (run from `make test`, a nested make says "Entering directory" unless told not to, and
    # would take the outer make's flags)
    env = {k: v for k, v in os.environ.items() if k not in ("MAKELEVEL", "MAKEFLAGS", "MFLAGS")}

    def make(*args):
        return subprocess.run(["make", "--no-print-directory", *args], cwd=root, capture_output=True,
                              text=True, timeout=60, env=env)
    bare = make("-n")                  # (dry runs first: a bare make that sets up would do it for real)
    assert bare.returncode == 0 and bare.stdout == make("-n", "help").stdout, bare.stdout
    assert all(line.startswith("echo ") for line in bare.stdout.splitlines()), bare.stdout
    helped = make("-s", "help")
    assert helped.returncode == 0, helped.stderr
    listed = re.findall(r"^make (\S+)", helped.stdout, re.M)
    with open(os.path.join(root, "Makefile")) as fh:
        phony = {t for line in fh if line.startswith(".PHONY:") for t in line.split()[1:]}
    assert set(listed) == phony - {"help"}, (listed, phony)
    for target in listed + ["test"]:               # (.ci/run calls make test)
        r = make("-n", target)
        assert r.returncode == 0, (target, r.stderr)
