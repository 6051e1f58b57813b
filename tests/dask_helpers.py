"""Real processes for the cluster tests: a `dask scheduler`, `dask worker`s and an S3 server
(moto's standalone server), each on a free 127.0.0.1 port, with bounded waits, always torn down."""

import contextlib
import os
import pathlib
import signal
import socket
import subprocess
import sys
import time
import urllib.request

BIN = pathlib.Path(sys.executable).parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(proc: subprocess.Popen) -> None:
    """SIGKILL the process group of ``proc`` (it was started in a new session)."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            pass
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)


@contextlib.contextmanager
def processes():
    """A list to append Popen objects to; all of them are killed on exit."""
    procs: list[subprocess.Popen] = []
    try:
        yield procs
    finally:
        for proc in reversed(procs):
            _stop(proc)


def spawn(cmd, log: pathlib.Path, env=None, own_session: bool = True) -> subprocess.Popen:
    """Start ``cmd`` in a new process group: in a new session (the default), or in this one
    (``own_session=False``: the same scheduler autogroup as this process, so that a benchmark's
    Dask workers get no more CPU share than its process pool)."""
    fh = open(log, "ab")
    group = {"start_new_session": True} if own_session else {"process_group": 0}
    return subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, env=env,
                            stdin=subprocess.DEVNULL, **group)


def start_dask(procs: list, tmp: pathlib.Path, n_workers: int = 2, timeout: float = 90,
               plain: bool = False, nthreads: int = 1, own_session: bool = True) -> str:
    """Start a scheduler and ``n_workers`` workers (one scene slot each, offering the ``scene``
    resource; ``plain``: started with no kubric flags, ``nthreads`` threads each); returns the
    address once every worker has joined."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs.append(spawn([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port",
                        str(port), "--no-dashboard"], tmp / "scheduler.log",
                       own_session=own_session))
    for k in range(n_workers):
        flags = ["--nthreads", str(nthreads)] + ([] if plain else ["--resources", "scene=1"])
        procs.append(spawn([str(BIN / "dask"), "worker", address, *flags, "--name", f"w{k}",
                            "--no-dashboard", "--host", "127.0.0.1", "--death-timeout", "60"],
                           tmp / f"worker{k}.log", own_session=own_session))
    from distributed import Client
    with Client(address, timeout=timeout) as client:
        client.wait_for_workers(n_workers, timeout=timeout)
    return address


def start_s3(procs: list, tmp: pathlib.Path, timeout: float = 60) -> str:
    """Start moto's S3 server; returns its endpoint URL once it answers."""
    port = free_port()
    procs.append(spawn([str(BIN / "moto_server"), "-H", "127.0.0.1", "-p", str(port)],
                       tmp / "moto.log"))
    endpoint = f"http://127.0.0.1:{port}"
    end = time.time() + timeout
    while True:
        try:
            urllib.request.urlopen(endpoint + "/moto-api/", timeout=2)
            return endpoint
        except OSError:
            if time.time() > end or procs[-1].poll() is not None:
                raise AssertionError(f"moto server did not start: {(tmp / 'moto.log').read_text()}") from None
            time.sleep(0.2)


def s3_env(endpoint: str) -> dict:
    """Environment that points fsspec / s3fs at ``endpoint`` (fsspec's own configuration)."""
    return {"FSSPEC_S3_ENDPOINT_URL": endpoint, "AWS_ACCESS_KEY_ID": "test",
            "AWS_SECRET_ACCESS_KEY": "test", "AWS_DEFAULT_REGION": "us-east-1"}


def point_at_s3(mp, endpoint: str, cache=None):
    """Point this process (its environment and fsspec's configuration, through the
    ``pytest.MonkeyPatch`` ``mp``) and its children at moto's ``endpoint``; with ``cache``, the
    dataset cache too. Returns a fresh ``s3fs.S3FileSystem``."""
    for key, value in s3_env(endpoint).items():
        mp.setenv(key, value)
    if cache is not None:
        mp.setenv("KUBRIC_CACHE_DIR", str(cache))
    import fsspec.config
    mp.setitem(fsspec.config.conf, "s3", {"endpoint_url": endpoint})
    import s3fs
    s3fs.S3FileSystem.clear_instance_cache()
    return s3fs.S3FileSystem()


def cmdline(pid: int) -> list[str]:
    try:
        return pathlib.Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")
    except OSError:
        return []


def ppid(pid: int) -> int:
    stat = pathlib.Path(f"/proc/{pid}/stat").read_text()
    return int(stat.rsplit(")", 1)[1].split()[1])


def kubric_workers(out) -> list[int]:
    """Pids of running `python -m kubric worker ... --out OUT` processes."""
    found = []
    for entry in pathlib.Path("/proc").iterdir():
        if entry.name.isdigit():
            cmd = cmdline(int(entry.name))
            if "kubric" in cmd and "worker" in cmd and str(out) in cmd:
                found.append(int(entry.name))
    return found


SLURM_TOOLS = ("munged", "slurmctld", "slurmd", "sbatch", "sinfo")


def slurm_missing() -> list[str]:
    import shutil
    return [t for t in SLURM_TOOLS if shutil.which(t, path=os.environ.get("PATH", "") +
                                                    ":/usr/sbin:/sbin") is None]


def start_slurm(procs: list, tmp: pathlib.Path, timeout: float = 60) -> dict:
    """A single-node Slurm (Debian's slurmctld + slurmd, authenticated by a private munged) with
    all state under ``tmp``; returns the environment (SLURM_CONF) for its client commands."""
    import shutil
    path = os.environ.get("PATH", "") + ":/usr/sbin:/sbin"
    tool = {t: shutil.which(t, path=path) for t in SLURM_TOOLS}
    for sub in ("state", "spool", "log"):
        (tmp / sub).mkdir(parents=True, exist_ok=True)
    key = tmp / "munge.key"
    key.write_bytes(os.urandom(1024))
    key.chmod(0o600)
    sock = tmp / "munge.sock"
    procs.append(spawn([tool["munged"], "--foreground", "--force", f"--key-file={key}",
                        f"--socket={sock}", f"--pid-file={tmp / 'munged.pid'}",
                        f"--log-file={tmp / 'log' / 'munged.log'}",
                        f"--seed-file={tmp / 'munged.seed'}"], tmp / "munged.out"))
    host = socket.gethostname()
    cpus = os.cpu_count() or 1
    conf = tmp / "slurm.conf"
    conf.write_text(f"""ClusterName=kubrictest
SlurmctldHost={host}(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={sock}
StateSaveLocation={tmp / 'state'}
SlurmdSpoolDir={tmp / 'spool'}
SlurmctldPidFile={tmp / 'slurmctld.pid'}
SlurmdPidFile={tmp / 'slurmd.pid'}
SlurmctldLogFile={tmp / 'log' / 'slurmctld.log'}
SlurmdLogFile={tmp / 'log' / 'slurmd.log'}
SlurmctldPort={free_port()}
SlurmdPort={free_port()}
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory=4000 State=UNKNOWN
PartitionName=kubric Nodes={host} Default=YES MaxTime=INFINITE State=UP
""")
    env = dict(os.environ, SLURM_CONF=str(conf))
    end = time.time() + timeout
    while not sock.exists():
        if time.time() > end or procs[-1].poll() is not None:
            raise AssertionError(f"munged did not start: {(tmp / 'munged.out').read_text()}")
        time.sleep(0.1)
    procs.append(spawn([tool["slurmctld"], "-D", "-f", str(conf)], tmp / "slurmctld.out", env))
    procs.append(spawn([tool["slurmd"], "-D", "-f", str(conf)], tmp / "slurmd.out", env))
    while True:
        state = subprocess.run([tool["sinfo"], "-h", "-o", "%T"], env=env, capture_output=True,
                               text=True, timeout=30).stdout.strip()
        if state == "idle":
            return env
        if time.time() > end:
            raise AssertionError(f"slurm did not come up (sinfo: {state!r}): "
                                 f"{(tmp / 'log' / 'slurmctld.log').read_text()[-2000:]}")
        time.sleep(0.5)
