"""Dask executor: a LocalCluster of 2 spawned workers renders the same bits as the in-process
executor, and a worker killed mid-run (SIGKILL) costs no frame."""
from __future__ import annotations

import os
import signal

import pytest
from batch_helpers import assert_bit_identical, frames_of, manifest

from draaw_mi.batch import runner as batch

distributed = pytest.importorskip("distributed", reason="Dask is an optional extra: pip install 'draaw-mi[batch]'")

FRAMES = 12


@pytest.fixture(scope="module")
def client():
    from draaw_mi.batch.executors import dask_client
    c, cluster, threads = dask_client(workers=2)
    assert threads == max(1, (os.cpu_count() or 1) // 2)
    yield c
    c.close()
    cluster.close()


def _doc(tmp_path):
    doc = manifest(tmp_path, frames=FRAMES, spp=8, aovs=["depth"])
    doc["output"] = "{job}/{frame:04d}.exr"
    return doc


def test_dask_frames_equal_inprocess_frames(tmp_path, client):
    doc = _doc(tmp_path)
    ref = batch.run(doc, out=str(tmp_path / "inprocess"), progress=False)
    assert ref.complete
    pids = set()
    res = batch.run(doc, out=str(tmp_path / "dask"), executor="dask", client=client, progress=False,
                    on_result=lambda r: pids.add(r["pid"]))
    assert res.complete and res.rendered == FRAMES and not res.failed
    assert os.getpid() not in pids and len(pids) == 2                # both workers rendered
    assert {r["threads"] for r in res.results} == {client.draaw_drjit_threads}   # workers x threads = cores
    assert_bit_identical(frames_of(tmp_path / "inprocess"), frames_of(tmp_path / "dask"))
    again = batch.run(doc, out=str(tmp_path / "dask"), executor="dask", client=client, progress=False)
    assert again.skipped == FRAMES and again.rendered == 0          # resumable on Dask too


def test_killing_a_worker_mid_run_loses_no_frame(tmp_path, client):
    doc = _doc(tmp_path)
    batch.run(doc, out=str(tmp_path / "inprocess"), progress=False)
    killed = []

    def kill_first_worker(r):
        if not killed and "pid" in r:
            killed.append(r["pid"])
            os.kill(r["pid"], signal.SIGKILL)                        # it is on its next frame by now

    res = batch.run(doc, out=str(tmp_path / "dask"), executor="dask", client=client, progress=False,
                    on_result=kill_first_worker)
    assert killed and res.complete and not res.failed, res.failed
    assert res.rendered == FRAMES
    assert killed[0] not in {r["pid"] for r in res.results[1:]}     # the dead worker rendered no more
    assert_bit_identical(frames_of(tmp_path / "inprocess"), frames_of(tmp_path / "dask"))


def test_cli_dask_executor_with_its_own_cluster(tmp_path, capsys):
    from batch_helpers import write_manifest

    from draaw_mi.cli import main
    doc = manifest(tmp_path, frames=2)
    path = write_manifest(tmp_path, doc)
    assert main(["batch", path, "--executor", "dask", "--workers", "1", "--no-progress"]) == 0
    assert "2 rendered" in capsys.readouterr().out
    assert len(frames_of(tmp_path / "out")) == 2


def test_existing_scheduler_address(tmp_path, client):
    doc = manifest(tmp_path, frames=2)
    res = batch.run(doc, executor="dask", scheduler=client.scheduler.address, progress=False)
    assert res.complete and res.rendered == 2
    assert all(r["pid"] != os.getpid() for r in res.results)


def test_two_runs_into_other_folders_share_no_task_key(tmp_path, client, monkeypatch):
    """The same manifest rendered into two folders on one scheduler: Dask merges tasks of one
    key, so a key made of the frame's content alone sent one run's frames to the other's files."""
    keys = []
    real = client.submit

    def recording(*args, **kwargs):
        keys.append(kwargs["key"])
        return real(*args, **kwargs)
    monkeypatch.setattr(client, "submit", recording)
    doc = manifest(tmp_path, frames=2)
    doc["output"] = "{job}/{frame:04d}.exr"
    runs = []
    for folder in ("a", "b"):
        keys.clear()
        res = batch.run(doc, out=str(tmp_path / folder), executor="dask", client=client, progress=False)
        assert res.complete and res.rendered == 2
        runs.append(set(keys))
    assert len(runs[0]) == 2 and not runs[0] & runs[1]


def test_a_runs_own_cluster_keeps_its_scratch_under_the_output_folder(tmp_path, monkeypatch):
    """A LocalCluster's scheduler and workers keep Dask's scratch space beside the run's log,
    under ``--out`` (Dask's default, ``dask-scratch-space`` in the temporary folder, left lock
    files outside it: the scheduler's global.lock and purge.lock, after a kill its
    scheduler-* folders), and the folder goes with the cluster."""
    import tempfile
    system_tmp = tmp_path / "system-tmp"
    system_tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(system_tmp))
    monkeypatch.setattr(tempfile, "tempdir", str(system_tmp))
    doc = manifest(tmp_path, frames=2)
    scratch_seen = []
    log = {}

    def during(r):
        scratch_seen.append(os.path.isdir(os.path.join(log["dir"], ".draaw-dask-scratch")))

    _, specs, _ = batch.load(doc)
    log["dir"] = os.path.dirname(batch.run(doc, dry_run=True, progress=False).log)
    res = batch.run(doc, executor="dask", workers=1, progress=False, on_result=during)
    assert res.complete and scratch_seen == [True, True]
    assert os.path.dirname(res.log) == log["dir"] and str(tmp_path) in log["dir"]
    assert not os.path.exists(os.path.join(log["dir"], ".draaw-dask-scratch"))
    # (the scenes' own scratch folders, draaw-mi-PID-*, live while this process holds them)
    assert [n for n in os.listdir(system_tmp) if not n.startswith("draaw-mi-")] == []


def test_a_cluster_that_fails_to_start_says_why_and_leaves_no_scratch(tmp_path, monkeypatch):
    """A script that called batch.run at its top level ran it again in every spawned worker
    (each stopped at the output lock), and the run ended in pages of "Nanny failed to start"
    tracebacks with `.draaw-dask-scratch` left under --out: the workers' imports are refused
    in one line, the run says what a script needs, and the scratch folder goes."""
    from draaw_mi.batch import executors
    from draaw_mi.errors import RenderError
    scratch = tmp_path / ".draaw-dask-scratch"

    def failing(*a, **k):
        scratch.mkdir()
        raise RuntimeError("Nanny failed to start.")
    monkeypatch.setattr(executors, "dask_client", failing)
    with pytest.raises(RenderError, match=r'failed to start\. A script .* under `if __name__ == "__main__":`'):
        executors.run_dask([], lambda r: None, workers=1, scratch=str(scratch))
    assert not scratch.exists()
    # a worker importing the script again (it runs as __mp_main__): refused in one line
    code = "from draaw_mi.batch.executors import refuse_in_a_workers_import\nrefuse_in_a_workers_import()\n"
    with pytest.raises(RenderError, match=r"batch.run: called while a worker process imports your script"):
        exec(compile(code, "script.py", "exec"), {"__name__": "__mp_main__"})
    exec(compile(code, "script.py", "exec"), {"__name__": "__main__"})           # a script's own run
