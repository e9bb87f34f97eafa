"""A Dask batch on a shared machine or farm: nothing of the run listens beyond loopback, its
dashboard is off unless asked (then on 127.0.0.1), a remote scheduler can be reached over TLS
(and refuses clients without the certificates), and a frame that kills every worker it runs on
ends as failed after the configured retries while the other frames finish, bit for bit."""
from __future__ import annotations

import ipaddress
import os
import threading
import time

import pytest
from batch_helpers import assert_bit_identical, frames_of, manifest

from draaw_mi.batch import runner as batch
from draaw_mi.batch.executors import dask_client

distributed = pytest.importorskip("distributed", reason="Dask is an optional extra: pip install 'draaw-mi[batch]'")
psutil = pytest.importorskip("psutil")

BAD = ("orbit", 1)                    # the frame that kills its worker


def listening(pids) -> set:
    """``(ip, port)`` of every listening TCP socket of the processes ``pids``."""
    out = set()
    for pid in pids:
        try:
            conns = psutil.Process(pid).net_connections(kind="inet")
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        out |= {(c.laddr.ip, c.laddr.port) for c in conns if c.status == psutil.CONN_LISTEN}
    return out


def this_run() -> list:
    me = psutil.Process()
    return [me.pid] + [c.pid for c in me.children(recursive=True)]


class KillsItsWorker(distributed.diagnostics.plugin.WorkerPlugin):
    """On every worker (restarted ones too): the frame task of ``BAD`` ends its process, as a
    renderer crash or the kernel's out-of-memory killer would; the others render as ever."""

    def setup(self, worker):
        import draaw_mi.batch.worker as w
        real = w.dask_render_frame

        def render(spec, threads=None):
            if (spec["job"], spec["frame"]) == BAD:
                time.sleep(0.5)      # long enough for a next task to reach a worker that queues
                os._exit(137)
            return real(spec, threads)
        w.dask_render_frame = render


def test_a_frame_that_kills_its_worker_fails_after_the_retries_and_nothing_listens_beyond_loopback(tmp_path):
    doc = manifest(tmp_path, frames=4)
    doc["output"] = "{job}/{frame:04d}.exr"
    ref = batch.run(doc, out=str(tmp_path / "inprocess"), progress=False)
    assert ref.complete
    client, cluster, _ = dask_client(workers=1, retries=1)
    try:
        assert cluster.scheduler.allowed_failures == 1                     # the configured retries
        client.register_plugin(KillsItsWorker())
        seen, done = set(), threading.Event()

        def poll():
            while not done.is_set():
                seen.update(listening(this_run()))
                time.sleep(0.05)
        watcher = threading.Thread(target=poll)
        watcher.start()
        t0 = time.perf_counter()
        try:
            res = batch.run(doc, out=str(tmp_path / "dask"), executor="dask", client=client, retries=1,
                            progress=False)
        finally:
            done.set()
            watcher.join()
        seconds = time.perf_counter() - t0
    finally:
        client.close()
        cluster.close()
    assert len(seen) >= 3, seen                     # scheduler, its HTTP routes, worker, nanny
    assert all(ipaddress.ip_address(ip).is_loopback for ip, _ in seen), seen
    assert not res.complete and res.rendered == 3 and seconds < 120
    [failed] = res.failed
    assert (failed["job"], failed["frame"]) == BAD and failed["error"].startswith("KilledWorker: the worker rendering it died")
    good = {k: v for k, v in frames_of(tmp_path / "inprocess").items() if k != "orbit/0001.exr"}
    assert_bit_identical(good, frames_of(tmp_path / "dask"))
    st = batch.status(doc, out=str(tmp_path / "dask"))
    assert st["counts"]["failed"] == 1 and "KilledWorker" in st["frames"][1]["error"]


def test_a_crash_takes_no_queued_frame_with_it(tmp_path):
    """Each task on a dying worker counts a failure: a worker that queued the next frame behind
    the crashing one (Dask's default) would report both killed. Ours hold one task at a time:
    with no retries, exactly the crashing frame fails."""
    doc = manifest(tmp_path, frames=4)
    doc["output"] = "{job}/{frame:04d}.exr"
    client, cluster, _ = dask_client(workers=1, retries=0)
    try:
        client.register_plugin(KillsItsWorker())
        res = batch.run(doc, out=str(tmp_path / "dask"), executor="dask", client=client, retries=0,
                        progress=False)
    finally:
        client.close()
        cluster.close()
    assert [(r["job"], r["frame"]) for r in res.failed] == [BAD] and res.rendered == 3


@pytest.fixture
def tls_files(tmp_path):
    """A temporary CA-signed certificate and key (Dask makes them), as files."""
    pytest.importorskip("cryptography")
    sec = distributed.Security.temporary()
    files = {}
    for key, text in (("ca_file", sec.tls_ca_file), ("cert", sec.tls_client_cert), ("key", sec.tls_client_key)):
        files[key] = str(tmp_path / f"{key}.pem")
        with open(files[key], "w") as fh:
            fh.write(text)
    return sec, files


def test_a_batch_over_tls_renders_the_in_process_frames_and_plain_clients_are_refused(tmp_path, tls_files):
    sec, files = tls_files
    doc = manifest(tmp_path, frames=2)
    doc["output"] = "{job}/{frame:04d}.exr"
    assert batch.run(doc, out=str(tmp_path / "inprocess"), progress=False).complete
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, protocol="tls://",
                                       host="127.0.0.1", security=sec, dashboard_address=None)
    try:
        address = cluster.scheduler_address
        assert address.startswith("tls://")
        res = batch.run(doc, out=str(tmp_path / "tls"), executor="dask", scheduler=address, tls=files,
                        progress=False)
        assert res.complete and res.rendered == 2
        assert_bit_identical(frames_of(tmp_path / "inprocess"), frames_of(tmp_path / "tls"))
        with pytest.raises((OSError, TimeoutError)):                # plain TCP to the TLS port
            distributed.Client(address.replace("tls://", "tcp://"), timeout="3s")
        with pytest.raises(batch.DraawError, match="cannot connect"):   # TLS without certificates
            batch.run(doc, out=str(tmp_path / "none"), executor="dask", scheduler=address, progress=False)
    finally:
        cluster.close()


@pytest.mark.parametrize("args, message", [
    (["--tls-cert", "c.pem"], "missing --tls-ca-file, --tls-key"),
    (["--tls-ca-file", "a", "--tls-cert", "b", "--tls-key", "c", "--executor", "dask", "--scheduler",
      "tcp://127.0.0.1:1"], "are for a --scheduler tls://HOST:PORT"),
    (["--retries", "-1"], "--retries -1: expected an integer >= 0"),
    (["--dashboard"], "draaw-mi: error: --dashboard: needs --executor dask"),
    (["--retries", "1"], "draaw-mi: error: --retries: needs --executor dask"),
    (["--workers", "1", "--retries", "1"], "draaw-mi: error: --workers, --retries: need --executor dask"),
    (["--dashboard", "--executor", "dask", "--scheduler", "tcp://127.0.0.1:1"], "--dashboard shows the LocalCluster"),
])
def test_the_cluster_flags_are_checked_in_one_line(tmp_path, capsys, args, message):
    from batch_helpers import write_manifest

    from draaw_mi.cli import main
    path = write_manifest(tmp_path, manifest(tmp_path, frames=1))
    assert main(["batch", path, "--no-progress", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and message in err, err
    assert not (tmp_path / "out").exists()


def _status_page(client) -> int:
    """The HTTP status of the scheduler's dashboard page (``/status``)."""
    import urllib.error
    import urllib.request
    port = client.cluster.scheduler.http_server.port
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/status", timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as e:
        return e.code


def test_the_dashboard_is_served_only_when_asked_and_only_on_loopback():
    """A plain dask run's LocalCluster serves no dashboard (it served one on every interface);
    Dask's own HTTP routes and every other socket listen on 127.0.0.1 only. (Without one first:
    once a dashboard was served, Dask serves its pages in later clusters of the process.)"""
    for asked in (False, True):
        client, cluster, _ = dask_client(workers=1, dashboard=asked)
        try:
            addresses = listening(this_run())
            assert addresses and all(ipaddress.ip_address(ip).is_loopback for ip, _ in addresses), addresses
            assert _status_page(client) == (200 if asked else 404), asked
            if asked:
                host = client.dashboard_link.split("//")[1].split(":")[0]
                assert ipaddress.ip_address(host).is_loopback, client.dashboard_link
        finally:
            client.close()
            cluster.close()


def test_retries_are_refused_where_no_worker_can_die(tmp_path):
    """An in-process run has no worker to lose: retries there would be ignored without a word."""
    from draaw_mi.errors import ParameterError
    doc = manifest(tmp_path, frames=1)
    with pytest.raises(ParameterError, match=r"^batch.run: retries=1 is for executor='dask'"):
        batch.run(doc, out=str(tmp_path / "out"), retries=1, progress=False)
    with pytest.raises(ParameterError, match=r"^batch.run: retries=-1; expected an integer >= 0"):
        batch.run(doc, out=str(tmp_path / "out"), executor="dask", retries=-1, progress=False)
    assert not (tmp_path / "out").exists()
