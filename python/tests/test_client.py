"""carvemap.client against real servers on loopback (conftest.LocalCluster: a merge service, a
coordinator with bearer tokens for tenants acme and beta, two workers): a scan written from
numpy arrays is submitted, watched to SUCCEEDED with progress, listed, fetched (byte for byte,
resumed, loaded), and a second job is cancelled; errors come back as JobError with gRPC's
code; a scan uploaded from here through a broken stream, resumed, and run. Then TLS: a coordinator serving TLS with a throw-away CA (tests/tools/make_test_pki.sh)."""
import filecmp
import os
import subprocess
import time

import pytest

from box_room import write_box_room
from carvemap.client import JobClient, JobError
from carvemap.outputs import load_outputs
from conftest import REPO, LocalCluster

TOKEN = "acme-" + "a" * 40
OTHER = "beta-" + "b" * 40


@pytest.fixture(scope="module")
def cluster(tmp_path_factory, carvemap_bin):
    c = LocalCluster(tmp_path_factory.mktemp("cluster"), {"acme": TOKEN, "beta": OTHER})
    # The input goes into acme's folder on the server's storage.
    write_box_room(os.path.join(c.data_root, "acme", "room.h5"), seconds=8.0)
    yield c
    c.stop()


@pytest.fixture(scope="module")
def finished(cluster):
    """The job run to the end while watched: (job, events)."""
    with JobClient(cluster.address, token=TOKEN) as client:
        job = client.submit("room.h5", output_name="numpy-room", idempotency_key="room-1",
                            object_resolution_m=0.0625)
        events = list(client.watch(job.job_id, min_interval_s=0.1, timeout_s=240))
        return job, events


def test_submit_and_watch_to_the_end(cluster, finished):
    job, events = finished
    assert job.state == "QUEUED" and job.tenant == "acme" and job.input_path == "room.h5"
    assert job.params["resolution_m"] == 0.0625  # the server's default, resolved
    assert job.params["object_resolution_m"] == 0.0625
    assert events[0].kind == "snapshot" and events[0].job.job_id == job.job_id
    assert [e.sequence for e in events] == list(range(1, len(events) + 1))
    order = ["QUEUED", "INGESTING", "CARVING", "MERGING", "SUCCEEDED"]
    changes = [e for e in events if e.kind == "state"]
    assert [e.to_state for e in changes] == \
        order[order.index(events[0].state) + 1:], cluster.log_tails()
    for e in changes:
        assert e.from_state in order and order.index(e.from_state) < order.index(e.to_state)
    assert events[-1].kind == "state" and events[-1].to_state == "SUCCEEDED"
    # Progress at most every 0.1 s: the job takes about a second, so a few events, how many
    # depends on the machine's speed.
    progress = [e for e in events if e.kind == "progress"]
    assert progress, "no progress event"
    assert any(e.chunks_total > 0 for e in progress) and any(e.stages for e in progress)
    assert all(0 <= e.chunks_done <= e.chunks_total for e in progress if e.chunks_total)
    assert all(0 <= e.rays_done <= e.rays_total for e in progress if e.rays_total)
    assert all(e.eta_s is None or e.eta_s >= 0 for e in progress)
    assert all(isinstance(str(e), str) and str(e) for e in events)


def test_get_list_and_idempotency(cluster, finished):
    job, _ = finished
    with JobClient(cluster.address, token=TOKEN) as client:
        got = client.get(job.job_id)
        assert got.state == "SUCCEEDED" and got.terminal and got.finished_unix_ms > 0
        assert got.chunks_done == got.chunks_total > 0
        again = client.submit("room.h5", output_name="numpy-room", idempotency_key="room-1",
                              object_resolution_m=0.0625)
        assert again.deduplicated and again.job_id == job.job_id
        assert job.job_id in [j.job_id for j in client.list()]
        assert [j.job_id for j in client.list(state="SUCCEEDED")] == [job.job_id]
        assert client.list(state="FAILED") == []
    with JobClient(cluster.address, token=OTHER) as beta:
        assert beta.list() == []
        with pytest.raises(JobError) as e:
            beta.get(job.job_id)  # another tenant's job answers as one that does not exist
        assert e.value.code == "NOT_FOUND"


def test_fetch_outputs(cluster, finished, tmp_path):
    job, _ = finished
    server = cluster.output_dir("acme", "numpy-room")
    with JobClient(cluster.address, token=TOKEN) as client:
        paths = client.fetch(job.job_id, tmp_path / "fetched", chunk_size_bytes=4096)
        fetched = load_outputs(tmp_path / "fetched")
        assert sorted(os.path.relpath(p, tmp_path / "fetched") for p in paths) == \
            sorted(fetched.outputs)
        for name in fetched.outputs:
            assert filecmp.cmp(os.path.join(server, name), fetched.path(name), shallow=False), name
        assert not [n for n in os.listdir(tmp_path / "fetched") if n.endswith(".partial")]
        # One level, one room: the box walked through.
        assert len(fetched.levels) == 1
        (room,) = fetched.rooms[0]
        assert 15 < room.area_m2 <= 24.5 and 2.4 < room.ceiling_z - room.floor_z < 2.8
        xs, ys = zip(*room.outline)
        assert -0.2 < min(xs) and max(xs) < 6.2 and -0.2 < min(ys) and max(ys) < 4.2
        # A download cut short resumes from its .partial file.
        dense = os.path.join(server, "mesh", "dense.ply")
        dest = tmp_path / "resumed" / "dense.ply"
        dest.parent.mkdir()
        with open(dense, "rb") as f:
            whole = f.read()
        (tmp_path / "resumed" / "dense.ply.partial").write_bytes(whole[:len(whole) // 3])
        client.fetch_file(job.job_id, "mesh/dense.ply", dest)
        assert dest.read_bytes() == whole
        with pytest.raises(JobError) as e:
            client.fetch_file(job.job_id, "no/such.ply", tmp_path / "x.ply")
        assert e.value.code == "NOT_FOUND"
        with pytest.raises(ValueError, match="not a relative path"):
            client.fetch(job.job_id, tmp_path / "x", names=["../escape"])


def test_cancel_a_second_job(cluster, finished):
    with JobClient(cluster.address, token=TOKEN) as client:
        second = client.submit("room.h5", output_name="to-cancel")
        cancelled = client.cancel(second.job_id, reason="not needed")
        assert cancelled.state == "CANCELLED"
        assert "not needed" in cancelled.error
        assert client.cancel(second.job_id).state == "CANCELLED"  # idempotent
        events = list(client.watch(second.job_id, timeout_s=30))
        assert [e.kind for e in events] == ["snapshot"] and events[0].state == "CANCELLED"
        assert [j.job_id for j in client.list(state="CANCELLED")] == [second.job_id]
        # Newest first, every page when a page holds one job.
        assert [j.job_id for j in client.list(page_size=1)][:2] == \
            [second.job_id, finished[0].job_id]
        with pytest.raises(JobError) as e:
            client.cancel(finished[0].job_id)
        assert e.value.code == "FAILED_PRECONDITION"


def test_errors(cluster):
    with JobClient(cluster.address, token="x" * 40) as bad:
        with pytest.raises(JobError) as e:
            bad.list()
        assert e.value.code == "UNAUTHENTICATED" and "x" * 20 not in e.value.details
    with JobClient(cluster.address) as anonymous:
        with pytest.raises(JobError) as e:
            anonymous.list()
        assert e.value.code == "UNAUTHENTICATED"
    with JobClient(cluster.address, token=TOKEN) as client:
        for call in (lambda: client.get("j-nope"),
                     lambda: list(client.watch("j-nope", timeout_s=10))):
            with pytest.raises(JobError) as e:
                call()
            assert e.value.code == "NOT_FOUND"
        with pytest.raises(JobError) as e:
            client.submit("missing.h5")
        assert e.value.code == "NOT_FOUND"
        with pytest.raises(JobError) as e:
            client.submit("../room.h5")
        assert e.value.code == "INVALID_ARGUMENT"
        with pytest.raises(JobError) as e:
            client.submit("room.h5", resolution_m=0.1)
        assert e.value.code == "INVALID_ARGUMENT"
        with pytest.raises(ValueError, match="evaluation 'slow': one of fast, exact"):
            client.submit("room.h5", evaluation="slow")


def test_token_from_the_environment(cluster, tmp_path, monkeypatch):
    token_file = tmp_path / "token"
    token_file.write_text(TOKEN + "\n")
    monkeypatch.setenv("CARVEMAP_SERVER", cluster.address)
    monkeypatch.setenv("CARVEMAP_TOKEN_FILE", str(token_file))
    with JobClient() as client:
        assert all(j.tenant == "acme" for j in client.list())


def test_upload_resumed_and_submitted(cluster, tmp_path):
    """A scan sent from here: the first stream breaks part-way (the progress callback raises
    inside the request iterator, so gRPC cancels the call); the upload resumes from the bytes
    the server holds, lands byte-identical in uploads/, and a job on its id runs to the end."""
    local = tmp_path / "room-here.h5"
    write_box_room(str(local), seconds=8.0)
    size = os.path.getsize(local)
    seen, broke = [], []

    def progress(received, total):
        seen.append(received)
        if not broke and received > size // 2:
            broke.append(received)
            raise ConnectionError("the network went away")

    with JobClient(cluster.address, token=TOKEN) as client:
        up = client.upload(local, name="sent.h5", chunk_size_bytes=64 << 10,
                           on_progress=progress)
        assert up.complete and up.input_path == "uploads/sent.h5" and up.size_bytes == size
        # After the break the next stream started where the server stood, not at 0.
        restart = seen.index(broke[0]) + 1
        assert 0 < seen[restart] <= broke[0]
        placed = os.path.join(cluster.data_root, "acme", "uploads", "sent.h5")
        assert filecmp.cmp(placed, local, shallow=False)
        assert client.upload(local, name="sent.h5").complete  # again: complete at once
        with JobClient(cluster.address, token=OTHER) as other:
            with pytest.raises(JobError) as e:
                other.submit(upload_id=up.upload_id)
            assert e.value.code == "NOT_FOUND"
        with pytest.raises(ValueError):
            client.submit("room.h5", upload_id=up.upload_id)
        job = client.submit(upload_id=up.upload_id, output_name="sent")
        assert job.input_path == "uploads/sent.h5"
        assert client.wait(job.job_id, timeout_s=240).state == "SUCCEEDED", cluster.log_tails()


def test_upload_to_no_server_fails_at_once(tmp_path):
    local = tmp_path / "x.h5"
    local.write_bytes(b"0123456789")
    start = time.monotonic()
    with JobClient("127.0.0.1:1", token=TOKEN) as client:
        with pytest.raises(JobError) as e:
            client.upload(local)
    assert e.value.code == "UNAVAILABLE"
    assert time.monotonic() - start < 20  # no resuming before the server ever answered


def test_tls(tmp_path_factory, carvemap_bin):
    pki = tmp_path_factory.mktemp("pki")
    subprocess.run(["bash", os.path.join(REPO, "tests", "tools", "make_test_pki.sh"), str(pki)],
                   check=True, capture_output=True)
    c = LocalCluster(tmp_path_factory.mktemp("tls"), {"acme": TOKEN}, workers=0, merge=False,
                     coordinator_args=["--tls-cert", pki / "server.crt",
                                       "--tls-key", pki / "server.key"])
    try:
        port = c.address.rsplit(":", 1)[1]
        with JobClient(c.address, token=TOKEN, tls_ca=pki / "ca.crt") as client:
            assert client.list() == []
            with pytest.raises(JobError) as e:
                client.get("j-nope")  # a round trip through TLS
            assert e.value.code == "NOT_FOUND"
        # Through a name the certificate carries, as through a port-forward.
        with JobClient(f"localhost:{port}", token=TOKEN, tls_ca=pki / "ca.crt",
                       tls_server_name="carvemap-coordinator") as client:
            assert client.list() == []
        for kwargs in (dict(tls_ca=pki / "other-ca.crt"),  # a CA that did not sign it
                       dict(tls_ca=pki / "ca.crt", tls_server_name="elsewhere.example"),
                       dict()):                             # plaintext to a TLS port
            with JobClient(c.address, token=TOKEN, timeout_s=10, **kwargs) as client:
                with pytest.raises(JobError) as e:
                    client.list()
                assert e.value.code == "UNAVAILABLE", kwargs
    finally:
        c.stop()
