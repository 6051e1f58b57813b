"""The Dask runner: the same worker contract as the local runner, on a Dask distributed cluster.

``kubric generate ... --cluster local|tcp://HOST:PORT|slurm``:

* ``local`` starts a ``LocalCluster`` in this process (``--workers`` slots); its scheduler,
  workers and dashboard listen on 127.0.0.1 only (``--dashboard-address :8787`` asks for every
  interface);
* ``tcp://HOST:PORT`` (or ``tls://``) joins a running scheduler, its workers as they are
  (:mod:`kubric.pipeline.dask_slots`: the ``scene`` resource where workers offer it, else
  ``nthreads // threads_per_scene`` slots per worker). A ``tcp://`` address is first probed: it
  must answer with Dask's handshake within ``--connect-timeout`` (the dashboard's port, 8787, or
  any other server is refused in one line, never a hang);
* ``slurm`` submits Dask worker jobs with dask-jobqueue (``--jobs``, ``--cores-per-job``,
  ``--memory``, ``--walltime``, ``--queue``, ``--job-directive``); every job runs
  ``cores-per-job // threads-per-scene`` worker processes.

Each Dask task (:func:`scene_task`) runs one scene in a **fresh** ``python -m kubric worker``
subprocess (Blender keeps state across scenes) with the per-scene timeout, and returns its log
text, which the client appends to ``OUT/logs/scene_{seed:08d}.log``. A worker slot renders one
scene at a time with ``--threads-per-scene`` render threads (``KUBRIC_RENDER_THREADS``); the
client keeps a bounded window of tasks in flight (:class:`~kubric.pipeline.dask_slots.SceneSlots`).
A scheduler that goes away mid-run ends the run with :class:`ClusterError` (complete scenes
stay; a rerun finishes the rest). A failed attempt is resubmitted up to ``--retries`` times; a
task whose worker dies is rerun elsewhere by the scheduler. Completeness is decided as locally:
exit status 0 and ``_SUCCESS`` present. SIGINT sets a cluster-wide stop event: queued scenes do
not start, running subprocesses are terminated (they delete their work directories).
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import sys
import tempfile
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field

from kubric.errors import UsageError
from kubric.io.scene_dir import scene_name
from kubric.pipeline.dask_slots import RESOURCE, SceneSlots, Slot
from kubric.pipeline.runner import PARENT_ENV, Runner, RunSummary, run_logged, usable_cores

#: the dashboard of a cluster started here: this machine only unless asked
LOCAL_DASHBOARD = "127.0.0.1:8787"
#: the largest handshake a Dask scheduler sends (it is about 60 bytes)
_HANDSHAKE_MAX = 1 << 16
_ADDRESS_RE = re.compile(r"^(tcp|tls)://([^\s:/]+|\[[0-9a-fA-F:]+\]):(\d{1,5})$")


class ClusterError(UsageError, ValueError):
    """A bad ``--cluster`` value or a cluster that cannot be reached or started (one line)."""


@dataclass
class ClusterOptions:
    """Everything ``--cluster`` and its flags say; see the module doc."""

    spec: str = "local"
    workers: int | None = None            # local: slots (default cores // threads_per_scene)
    threads_per_scene: int = 1
    connect_timeout: float = 20.0
    dashboard_address: str = LOCAL_DASHBOARD
    jobs: int = 1                         # slurm
    cores_per_job: int = 1
    memory: str = "4GB"
    walltime: str = "01:00:00"
    queue: str | None = None
    job_directives: list[str] = field(default_factory=list)

    @property
    def kind(self) -> str:
        if self.spec in ("local", "slurm"):
            return self.spec
        if _ADDRESS_RE.match(self.spec):
            return "address"
        raise ClusterError(f"--cluster {self.spec!r}: expected local, slurm or a scheduler "
                           f"address tcp://HOST:PORT (or tls://HOST:PORT)")

    def validate(self) -> None:
        kind = self.kind
        for name in ("threads_per_scene", "jobs", "cores_per_job"):
            if getattr(self, name) < 1:
                raise ClusterError(f"--{name.replace('_', '-')} must be ≥ 1, got "
                                   f"{getattr(self, name)}")
        if self.workers is not None and self.workers < 1:
            raise ClusterError(f"--workers must be ≥ 1, got {self.workers}")
        if self.connect_timeout <= 0:
            raise ClusterError(f"--connect-timeout must be > 0, got {self.connect_timeout}")
        if kind == "address" and int(_ADDRESS_RE.match(self.spec).group(3)) > 65535:
            raise ClusterError(f"--cluster {self.spec!r}: port must be ≤ 65535")
        if kind == "slurm" and self.cores_per_job < self.threads_per_scene:
            raise ClusterError(f"--cores-per-job {self.cores_per_job} is less than "
                               f"--threads-per-scene {self.threads_per_scene}")
        from kubric.extras import require  # one line naming the extra, before any cluster
        require(f"--cluster {self.spec}", "dask", "distributed",
                *(["dask_jobqueue"] if kind == "slurm" else []))

    def slurm_kwargs(self) -> dict:
        """dask-jobqueue ``SLURMCluster`` arguments: one Dask worker process per scene slot,
        each offering the ``scene=1`` resource."""
        return dict(cores=self.cores_per_job,
                    processes=max(1, self.cores_per_job // self.threads_per_scene),
                    memory=self.memory, walltime=self.walltime, queue=self.queue,
                    job_extra_directives=list(self.job_directives), python=sys.executable,
                    worker_extra_args=["--resources", f"{RESOURCE}=1"],
                    job_name="kubric-worker", scheduler_options={"dashboard_address":
                                                                 self.dashboard_address})


def _quiet(silent: bool = False):
    """Dask's loggers at ERROR (or, ``silent``, at nothing: the run already failed in one
    line). Call it after importing distributed, whose import sets these levels from its config."""
    import logging

    import distributed  # noqa: F401  (its logging config first, ours over it)
    names = {"distributed", "distributed.scheduler", "distributed.worker", "bokeh", "tornado",
             "distributed.nanny", "distributed.core", "distributed.client",
             "distributed.batched", "distributed.comm", "distributed.comm.tcp"}
    if silent:
        names |= {n for n in logging.root.manager.loggerDict if n.startswith("distributed")}
    for name in names:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1 if silent else logging.ERROR)


def slurm_job_script(options: ClusterOptions) -> str:
    """The sbatch script dask-jobqueue would submit for ``options`` (nothing is submitted)."""
    from dask_jobqueue import SLURMCluster
    _quiet()
    cluster = SLURMCluster(**options.slurm_kwargs())
    try:
        return cluster.job_script()
    finally:
        cluster.close()


def open_cluster(options: ClusterOptions, processes: bool = False):
    """(client, cluster or None) for ``options``; raises :class:`ClusterError` (one line).
    ``processes``: a ``local`` cluster's workers are processes (for work done in the task itself,
    as packing), not threads of this process (enough for tasks that wait for a subprocess)."""
    options.validate()
    kind = options.kind
    if kind == "slurm" and shutil.which("sbatch") is None:
        raise ClusterError("--cluster slurm: sbatch is not on the PATH (run on a Slurm login node, "
                           "or use --print-job-script to see the job script)")
    from distributed import Client, LocalCluster
    _quiet()  # after the import: importing distributed sets its loggers' levels from its config
    cluster = None
    try:
        if kind == "local":
            slots = options.workers or max(1, usable_cores() // options.threads_per_scene)
            # every listener on 127.0.0.1: the scheduler (processes: tcp; threads: inproc, no
            # socket), the workers' own dashboards, and the dashboard unless asked otherwise
            local = {"host": "127.0.0.1"} if processes else {}
            cluster = LocalCluster(n_workers=slots, threads_per_worker=1, processes=processes,
                                   resources={RESOURCE: 1},
                                   dashboard_address=options.dashboard_address,
                                   worker_dashboard_address="127.0.0.1:0", silence_logs=40,
                                   **local)
            client = Client(cluster)
        elif kind == "slurm":
            from dask_jobqueue import SLURMCluster
            cluster = SLURMCluster(**options.slurm_kwargs())
            cluster.scale(jobs=options.jobs)
            client = Client(cluster)
        else:
            probe_scheduler(options.spec, options.connect_timeout)
            client = Client(options.spec, timeout=options.connect_timeout)
    except (OSError, TimeoutError) as err:
        if cluster is not None:
            cluster.close()
        what = f"no Dask scheduler answered at {options.spec}" if kind == "address" \
            else f"could not start the {kind} cluster"
        detail = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise ClusterError(f"--cluster: {what} within {options.connect_timeout:g} s ({detail})") \
            from None
    return client, cluster


def probe_scheduler(address: str, timeout: float) -> None:
    """Raise :class:`ClusterError` unless ``tcp://HOST:PORT`` answers with a Dask handshake within
    ``timeout`` seconds. A Dask scheduler sends its handshake (an 8-byte length, then frames
    holding msgpack with ``compression`` / ``python`` / ``pickle-protocol``) as soon as a
    connection opens; an HTTP server (the dashboard, port 8787) waits for a request, so it times
    out here instead of hanging in the client, and a server that sends something else is refused
    by its first bytes (the client would read them as a length: "Unable to allocate 3.07 EiB").
    ``tls://`` addresses are not probed (the handshake is inside TLS)."""
    match = _ADDRESS_RE.match(address)
    if match is None or match.group(1) != "tcp":
        return
    host, port = match.group(2).strip("[]"), int(match.group(3))
    deadline = time.monotonic() + timeout
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except OSError as err:
        raise ClusterError(f"--cluster: no Dask scheduler answered at {address} within "
                           f"{timeout:g} s ({err.strerror or type(err).__name__})") from None
    data = b""
    with sock:
        try:
            while len(data) < 8 or len(data) < 8 + min(_HANDSHAKE_MAX, int.from_bytes(
                    data[:8], "little")):
                if len(data) >= 8 and int.from_bytes(data[:8], "little") > _HANDSHAKE_MAX:
                    break
                sock.settimeout(max(0.01, deadline - time.monotonic()))
                block = sock.recv(4096)
                if not block:
                    break
                data += block
        except TimeoutError:
            raise ClusterError(
                f"--cluster {address}: something listens there but sent no Dask handshake within "
                f"--connect-timeout {timeout:g} s; is it the dashboard (port 8787)? A scheduler "
                "listens on 8786 by default") from None
        except OSError as err:
            raise ClusterError(f"--cluster {address}: the connection failed before a Dask "
                               f"handshake ({err.strerror or type(err).__name__})") from None
    if b"pickle-protocol" not in data[8:8 + _HANDSHAKE_MAX]:
        raise ClusterError(f"--cluster {address}: answered, but not as a Dask scheduler (its "
                           f"first bytes: {data[:24]!r})")


def dashboard_link(client, cluster, options: ClusterOptions) -> str:
    """The dashboard's address as it listens: for a cluster started here, the host of
    ``--dashboard-address`` (127.0.0.1 by default; every interface for ``:PORT``) and the port it
    got (Dask's own link names the machine's host name, whatever the bind)."""
    port = getattr(getattr(cluster, "scheduler", None), "http_server", None)
    port = getattr(port, "port", None)
    if options.kind != "local" or port is None:
        return client.dashboard_link
    host = options.dashboard_address.rpartition(":")[0] or "0.0.0.0"
    return f"http://{host}:{port}/status"


def scheduler_lost(client, kept: str) -> ClusterError | None:
    """A :class:`ClusterError` (one line; ``kept`` says what survives) when ``client`` has lost
    its scheduler, else None. Dask's own logging is silenced then: closing such a client logs
    tracebacks after the run has already failed in one line."""
    if client.status in ("running", "newly-created"):
        return None
    _quiet(silent=True)
    return ClusterError(f"the Dask scheduler at {client.scheduler.address} went away mid-run "
                        f"(client {client.status}); {kept}: start it again and rerun the same "
                        "command")


# ---------------------------------------------------------------------- on the Dask worker
def scene_task(cmd: Sequence[str], attempt: int, timeout: float | None, threads: int,
               stop_event: str | None = None, poll: float = 5.0) -> dict:
    """Run one worker attempt in a fresh subprocess on this Dask worker; returns
    ``{"rc", "log", "host"}`` (``rc`` None when the run was stopped before it started)."""
    where = socket.gethostname()
    event = None
    try:
        from distributed import Event, get_worker
        where = f"{get_worker().address} on {where}"
        if stop_event:
            event = Event(stop_event)
    except (ImportError, ValueError):
        pass
    should_stop = (lambda: event.is_set()) if event is not None else None

    def start(command, **kwargs):
        if should_stop is not None and should_stop():
            return None
        import subprocess
        return subprocess.Popen(command, **kwargs)

    env = dict(os.environ, **{PARENT_ENV: str(os.getpid()), "KUBRIC_RENDER_THREADS":
                              str(threads), "OMP_NUM_THREADS": str(threads),
                              "KUBRIC_DEBUG": "1"})  # the traceback of a failure in the log
    fd, log = tempfile.mkstemp(prefix="kubric-scene-", suffix=".log")
    os.close(fd)
    try:
        rc = run_logged(cmd, log, attempt, timeout, env, start=start, should_stop=should_stop,
                        poll=poll, where=f" on {where}")
        with open(log, errors="replace") as fh:
            text = fh.read()
    finally:
        os.remove(log)
    return {"rc": rc, "log": text, "host": where}


# ---------------------------------------------------------------------- on the client
class DaskRunner(Runner):
    """Run ``recipe_spec`` for ``seeds`` as Dask tasks through ``client`` (see module doc)."""

    def __init__(self, recipe_spec: str, out_root, seeds: Sequence[int], client,
                 assignments: Sequence[str] = (), retries: int = 2, timeout: float | None = None,
                 progress: bool = True, threads_per_scene: int = 1, resume: str = "same"):
        super().__init__(recipe_spec, out_root, seeds, assignments, retries, timeout, progress,
                         resume)
        if threads_per_scene < 1:
            raise ValueError(f"threads_per_scene must be ≥ 1, got {threads_per_scene}")
        self.client = client
        self.threads_per_scene = threads_per_scene
        self.run_id = uuid.uuid4().hex[:8]
        self.poll = 5.0   # seconds between a running task's checks of the stop event

    def _submit(self, seed: int, attempt: int, slot: Slot):
        return self.client.submit(
            scene_task, self.command(seed), attempt, self.timeout, self.threads_per_scene,
            f"kubric-stop-{self.run_id}", self.poll, pure=False,
            key=f"{scene_name(seed)}-attempt{attempt}-{self.run_id}", **slot.kwargs)

    def _finish(self, future, seed: int, attempt: int, summary: RunSummary, bar) -> bool:
        """Book one finished task; True when the scene is to be tried again."""
        try:
            result = future.result()
            rc, text = result["rc"], result["log"]
        except Exception as err:  # KilledWorker, CancelledError, a lost connection, ...
            self._check_scheduler()
            rc = None
            text = (f"=== attempt {attempt} lost: {type(err).__name__}: "
                    f"{str(err).splitlines()[0] if str(err) else ''}\n")
        self.logs.append(seed, text)
        if self._stop.is_set() and rc != 0:
            return False
        ok = rc == 0 and self.scene_complete(seed)
        if not ok and attempt <= self.retries:
            return True
        self._record(seed, ok, summary, bar)
        return False

    def _check_scheduler(self) -> None:
        """Raise :class:`ClusterError` when the client has lost its scheduler."""
        lost = scheduler_lost(self.client, "complete scenes are kept")
        if lost is not None:
            raise lost

    def _execute(self, todo: list[int], summary: RunSummary, bar) -> None:
        """Keep the cluster's scene slots busy from a queue of (seed, attempt); only a bounded
        window of futures exists at any time (:class:`SceneSlots`)."""
        from collections import deque

        from distributed import Event, wait
        event = Event(f"kubric-stop-{self.run_id}", client=self.client)
        slots = SceneSlots(self.client, self.threads_per_scene)
        queue = deque((seed, 1) for seed in todo)
        pending: dict = {}   # future -> (seed, attempt, slot)
        stop_seen = None
        while queue or pending:
            if self._stop.is_set() and stop_seen is None:
                stop_seen = time.monotonic()
                event.set()
                queue.clear()
            if stop_seen is not None and time.monotonic() - stop_seen > self.poll + self.kill_after:
                self.client.cancel(list(pending))
                break
            while queue:
                slot = slots.take()
                if slot is None:
                    break
                seed, attempt = queue.popleft()
                pending[self._submit(seed, attempt, slot)] = (seed, attempt, slot)
                summary.attempts += 1
            finished = [f for f in pending if f.done()]
            if not finished:
                if not pending:
                    self._check_scheduler()
                    time.sleep(0.2)   # no slot yet (no workers): look again
                    continue
                try:
                    wait(list(pending), timeout=0.5, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    pass
                except Exception:  # FuturesCancelledError: lost the scheduler?
                    self._check_scheduler()
                continue
            for future in finished:
                seed, attempt, slot = pending.pop(future)
                slots.give_back(slot)
                if self._finish(future, seed, attempt, summary, bar):
                    queue.appendleft((seed, attempt + 1))
                future.release()
        if stop_seen is not None:
            time.sleep(0.5)


__all__ = ["ClusterError", "ClusterOptions", "DaskRunner", "dashboard_link", "open_cluster",
           "probe_scheduler", "scene_task", "scheduler_lost",
           "slurm_job_script", "RESOURCE"]
