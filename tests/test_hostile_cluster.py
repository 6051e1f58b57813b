"""Round-two hostile tests (issue #27) of `--cluster` and `generate`: an address that is not a
Dask scheduler is refused within --connect-timeout, every listener of a local cluster is on
127.0.0.1 (and the printed dashboard says where it is), one `generate` per output folder, and no
Dask scratch space left behind by `pack --cluster local`."""

import os
import pathlib
import socket
import subprocess
import sys
import threading
import time

import psutil
import pytest
from hostile_fixtures import kubric, make_scenes

from kubric.io.output_lock import OutputLock
from kubric.pipeline.dask_runner import ClusterError, ClusterOptions, open_cluster, probe_scheduler
from kubric.pipeline.runner import LOCK_FILE

ROOT = pathlib.Path(__file__).resolve().parents[1]
FAKE = f"{ROOT / 'tests' / 'fake_recipes.py'}:Fake"


class FakeServer:
    """A TCP server on 127.0.0.1 that accepts and then says nothing, or ``greeting``."""

    def __init__(self, greeting: bytes = b""):
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.greeting = greeting
        self.conns = []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(conn)
            if self.greeting:
                conn.sendall(self.greeting)

    def close(self):
        self.sock.close()
        for c in self.conns:
            c.close()


def test_item6_silent_and_http_ports_are_refused_within_the_timeout():
    silent = FakeServer()
    http = FakeServer(b"HTTP/1.1 200 OK\r\nContent-Type: text/html\r\n\r\n<html>dashboard</html>")
    try:
        start = time.monotonic()
        with pytest.raises(ClusterError, match=r"sent no Dask handshake within --connect-timeout "
                           r"1.5 s; is it the dashboard"):
            probe_scheduler(f"tcp://127.0.0.1:{silent.port}", 1.5)
        assert time.monotonic() - start < 5
        with pytest.raises(ClusterError, match=r"answered, but not as a Dask scheduler \(its "
                           r"first bytes: b'HTTP/1.1 200 OK"):
            probe_scheduler(f"tcp://127.0.0.1:{http.port}", 1.5)
        # the command: one line, exit 2, within the timeout (not a hang, not 3.07 EiB)
        start = time.monotonic()
        run = subprocess.run([sys.executable, "-m", "kubric", "generate", FAKE, "--out",
                              "/tmp/unused", "--scenes", "1", "--cluster",
                              f"tcp://127.0.0.1:{silent.port}", "--connect-timeout", "2"],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 2 and len(run.stderr.strip().splitlines()) == 1, run.stderr
        assert "sent no Dask handshake" in run.stderr
        assert time.monotonic() - start < 60
    finally:
        silent.close()
        http.close()
    free = socket.socket()
    free.bind(("127.0.0.1", 0))
    port = free.getsockname()[1]
    free.close()
    with pytest.raises(ClusterError, match=f"no Dask scheduler answered at tcp://127.0.0.1:{port}"):
        probe_scheduler(f"tcp://127.0.0.1:{port}", 1.0)


def _listeners():
    me = psutil.Process()
    return sorted({(c.laddr.ip, c.laddr.port) for p in [me, *me.children(recursive=True)]
                   for c in p.net_connections("inet") if c.status == "LISTEN"})


@pytest.mark.parametrize("processes", [False, True])
def test_item9_local_cluster_listens_on_localhost_only(processes):
    before = set(_listeners())
    client, cluster = open_cluster(ClusterOptions(spec="local", workers=1,
                                                  dashboard_address="127.0.0.1:0"), processes)
    try:
        from kubric.pipeline.dask_runner import dashboard_link
        mine = [addr for addr in _listeners() if addr not in before]
        link = dashboard_link(client, cluster, ClusterOptions(spec="local",
                                                              dashboard_address="127.0.0.1:0"))
        probe_scheduler(cluster.scheduler_address, 5) if processes else None  # a real one passes
    finally:
        client.close()
        cluster.close()
    assert mine and all(ip == "127.0.0.1" for ip, _ in mine), mine
    port = int(link.rsplit(":", 1)[1].split("/")[0])
    assert link.startswith("http://127.0.0.1:") and ("127.0.0.1", port) in mine


def test_item10_second_generate_on_one_output_refuses(tmp_path):
    out = tmp_path / "out"
    with OutputLock(out / LOCK_FILE, "x"):
        run = subprocess.run([sys.executable, "-m", "kubric", "generate", FAKE, "--out",
                              str(out), "--scenes", "2", "--no-progress"],
                             capture_output=True, text=True, timeout=120)
    assert run.returncode == 3, run.stderr
    line, = run.stderr.strip().splitlines()
    assert line.startswith(f"kubric generate: error: --out {str(out)!r} is being written by "
                           f"another run (pid {os.getpid()}")
    assert not list(out.glob("scene_*"))
    run = subprocess.run([sys.executable, "-m", "kubric", "generate", FAKE, "--out", str(out),
                          "--scenes", "2", "--no-progress"], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert sorted(p.name for p in out.iterdir()) == ["logs", "scene_00000000", "scene_00000001"]


@pytest.mark.slow  # a LocalCluster with worker processes: ~20 s
def test_item11_pack_on_local_cluster_leaves_no_scratch(tmp_path):
    scenes = make_scenes(tmp_path / "scenes", 3)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    run = kubric("pack", scenes, "--out", tmp_path / "ds", "--splits", "train=1", "--cluster",
                 "local", "--workers", "1", "--no-progress", env={"TMPDIR": str(tmp)},
                 timeout=300)
    assert run.returncode == 0, run.stderr
    assert "Dask dashboard: http://127.0.0.1:" in run.stdout
    assert list(tmp.iterdir()) == []


def test_item10_two_real_generates_at_once(tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "kubric", "generate", FAKE, "--out", str(out), "--scenes", "2",
           "--workers", "1", "--no-progress", "--set", "sleep=1.5"]
    first = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (out / LOCK_FILE).exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    second = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert first.poll() is None, "the first run ended before the second started"
    assert second.returncode == 3 and f"(pid {first.pid}," in second.stderr  # busy (docs/exit-codes.md)
    stdout, _ = first.communicate(timeout=120)
    assert first.returncode == 0 and stdout.startswith("2 generated, 0 already complete")
