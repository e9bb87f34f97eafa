"""Scratch folders of scenes (``scene.loading.ScratchFolder``): a process killed with SIGKILL
runs no finaliser, so the folder its scene made stays; the next process's first scratch folder
removes it, and only folders whose owner no longer holds them."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile

import pytest

from draaw_mi.scene.loading import ScratchFolder, sweep_scratch_folders

HOLDER = """
import sys, time
from draaw_mi.scene.loading import ScratchFolder
f = ScratchFolder()
print(f.name, flush=True)
time.sleep(600)
"""


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX signals")
def test_a_killed_processs_scratch_folder_is_swept_and_a_live_ones_is_not(tmp_path):
    env = dict(os.environ, TMPDIR=str(tmp_path))
    procs = [subprocess.Popen([sys.executable, "-c", HOLDER], stdout=subprocess.PIPE, text=True, env=env)
             for _ in range(2)]
    try:
        folders = [p.stdout.readline().strip() for p in procs]
        assert all(os.path.isdir(f) and f.startswith(str(tmp_path)) for f in folders), folders
        procs[0].send_signal(signal.SIGKILL)
        procs[0].wait()
        assert os.path.isdir(folders[0])                         # (no finaliser ran)
        mine = tempfile.mkdtemp(prefix="draaw-mi-", dir=tmp_path)   # no owner file: not judged
        assert sweep_scratch_folders(str(tmp_path)) == [folders[0]]
        assert not os.path.exists(folders[0]) and os.path.isdir(folders[1]) and os.path.isdir(mine)
    finally:
        for p in procs:
            p.kill()
            p.wait()
            p.stdout.close()


def test_a_scratch_folder_holds_its_owner_file_until_it_goes():
    folder = ScratchFolder()
    path = folder.name
    assert os.path.isfile(os.path.join(path, ".owner"))
    assert sweep_scratch_folders(os.path.dirname(path)) == []        # held by this process
    folder.cleanup()
    assert not os.path.exists(path)
