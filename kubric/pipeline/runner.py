"""Runners: many scenes, one fresh ``python -m kubric worker`` process per scene.

:class:`Runner` holds what every runner shares (output root as a path or fsspec URL, per-scene
logs, resume, progress bar, summary, signals); :class:`LocalRunner` is the process pool below,
:class:`kubric.pipeline.dask_runner.DaskRunner` the same on a Dask cluster. The local runner:

* a pool of ``workers`` concurrent processes (default: the usable cores);
* a tqdm progress bar with ETA and the failure count;
* up to ``retries`` extra attempts per failed scene;
* one log per scene, kept, in ``OUT/logs/scene_{seed:08d}.log`` (all attempts appended);
* resume: complete scenes are skipped, stale work directories removed — when they were made
  with this run's options (else the run refuses: :mod:`kubric.pipeline.resume_check`);
* one run per output folder: ``OUT/.kubric-generate.lock`` is held while the run lasts; a second
  run on the same folder refuses at once (:class:`~kubric.io.output_lock.OutputBusy`);
* SIGINT / SIGTERM: no new scenes start, running workers are terminated (they delete their work
  directories), and the summary says so. Even a ``kill -9`` of the runner leaves no directory that
  looks complete: only ``_SUCCESS`` marks a scene done, and the workers die with the runner
  (Linux parent-death signal).
"""

from __future__ import annotations

import abc
import os
import pathlib
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

from kubric.io import storage
from kubric.io.output_lock import OutputLock
from kubric.io.scene_dir import complete_scenes, is_complete, scene_name
from kubric.pipeline.resume_check import (
    RESUME_MODES,
    check_same_options,
    remove_requested,
    run_options,
)
from kubric.pipeline.worker import remove_stale

#: environment variable telling a worker to die with the runner that started it.
PARENT_ENV = "KUBRIC_RUNNER_PID"
#: the lock file a run holds in its (local) output folder
LOCK_FILE = ".kubric-generate.lock"


def usable_cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


@dataclass
class RunSummary:
    """What a run did. ``failed`` maps seed → log path."""

    requested: int = 0
    done: list[int] = field(default_factory=list)
    skipped: list[int] = field(default_factory=list)
    failed: dict[int, pathlib.Path] = field(default_factory=dict)
    replaced: int = 0    # complete scenes deleted to be made again (--overwrite)
    attempts: int = 0
    interrupted: bool = False
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.failed and not self.interrupted

    def format(self, out_root) -> str:
        lines = [f"{len(self.done)} generated, {len(self.skipped)} already complete, "
                 f"{len(self.failed)} failed of {self.requested} scenes in {self.seconds:.1f} s "
                 f"({self.attempts} worker runs) → {out_root}"]
        if self.replaced:
            lines[0] += f" ({self.replaced} complete scenes replaced: --overwrite)"
        if self.interrupted:
            lines.append("interrupted: run the same command again to finish the remaining scenes")
        for seed, log in sorted(self.failed.items()):
            lines.append(f"  FAILED {scene_name(seed)}: {_last_line(log)}  (log: {log})")
        return "\n".join(lines)


def _last_line(log: pathlib.Path) -> str:
    """Why the last attempt in ``log`` failed: its timeout, else its last line of output, else
    its exit status."""
    try:
        lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return "no log"
    starts = [i for i, ln in enumerate(lines) if ln.startswith("=== attempt ")]
    last = lines[starts[-1] + 1:] if starts else lines
    markers = [ln[4:] for ln in last if ln.startswith("=== ")]
    timed_out = [m for m in markers if m.startswith("timed out")]
    if timed_out:
        return f"{timed_out[0]} (--timeout)"
    output = [ln for ln in last if not ln.startswith("=== ")]
    if output:
        return output[-1][:200]
    return markers[-1] if markers else "empty log"


def recipe_import_root(recipe_spec: str) -> str | None:
    """The folder this process imported a ``module:Class`` recipe's top-level module from (the
    worker puts it first on its path, having no current directory there), or None for a
    registered name, a ``file.py:Class`` or a module of kubric's."""
    module, sep, _ = recipe_spec.rpartition(":")
    top = module.split(".")[0]
    if not sep or top == "kubric" or module.endswith(".py") or pathlib.Path(module).is_file():
        return None
    loaded = sys.modules.get(top)
    where = list(getattr(loaded, "__path__", None) or []) or [getattr(loaded, "__file__", None)]
    return str(pathlib.Path(where[0]).resolve().parent) if where[0] else None


def worker_command(recipe_spec: str, seed: int, out_root, assignments: Sequence[str]) -> list[str]:
    """The worker's command line. ``-P``: the current directory is not put first on the worker's
    ``sys.path``, so a folder named ``kubric`` there (the clone, run from its parent) cannot
    shadow the installed package as a namespace package; the worker imports what the runner did."""
    cmd = [sys.executable, "-P", "-m", "kubric", "worker", recipe_spec, "--seed", str(seed),
           "--out", str(out_root)]
    root = recipe_import_root(recipe_spec)
    if root is not None:
        cmd += ["--recipe-path", root]
    for a in assignments:
        cmd += ["--set", a]
    return cmd


def wait_exit(proc: subprocess.Popen, timeout: float | None) -> bool:
    """Wait up to ``timeout`` seconds (None: for ever) for ``proc`` to exit and reap it; True when
    it has exited. Wakes the moment it exits: on Linux through a pidfd, where ``Popen.wait(timeout)``
    polls with sleeps of up to 50 ms (measured: +34 ms per scene for Dask tasks, which wait with a
    timeout to poll their stop event, against the pool's plain wait)."""
    if timeout is None:
        proc.wait()
        return True
    try:
        fd = os.pidfd_open(proc.pid)
    except (AttributeError, OSError):  # not Linux ≥ 5.3, or the process is already reaped
        try:
            proc.wait(timeout=timeout)
            return True
        except subprocess.TimeoutExpired:
            return False
    try:
        ready, _, _ = select.select([fd], [], [], timeout)
    finally:
        os.close(fd)
    if ready:
        proc.wait()
        return True
    return proc.poll() is not None


def run_logged(cmd: Sequence[str], log: pathlib.Path, attempt: int, timeout: float | None = None,
               env: dict | None = None, start=None, should_stop=None, poll: float = 2.0,
               where: str = "") -> int | None:
    """Run one worker attempt with stdout+stderr appended to ``log`` between ``=== attempt`` and
    ``=== exit status`` lines; kill it after ``timeout`` seconds or once ``should_stop()`` is
    true (polled every ``poll`` s). ``start(cmd, **popen_kwargs)`` replaces ``subprocess.Popen``
    (returning None = do not start). Returns the exit status, None when not started."""
    start = start or subprocess.Popen
    with open(log, "a") as fh:
        fh.write(f"=== attempt {attempt} at {time.strftime('%Y-%m-%d %H:%M:%S')}{where}: "
                 f"{' '.join(cmd)}\n")
        fh.flush()
        proc = start(list(cmd), stdout=fh, stderr=subprocess.STDOUT, env=env,
                     stdin=subprocess.DEVNULL)
        if proc is None:
            return None
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            if should_stop is not None:
                wait = poll if wait is None else min(wait, poll)
            if wait_exit(proc, wait):
                rc = proc.returncode
                break
            if deadline is not None and time.monotonic() >= deadline:
                proc.kill()
                rc = proc.wait()
                fh.write(f"=== timed out after {timeout} s\n")
                break
            if should_stop is not None and should_stop():
                proc.terminate()
                try:
                    rc = proc.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    rc = proc.wait()
                fh.write("=== stopped: the run was interrupted\n")
                break
        fh.write(f"=== exit status {rc}\n")
    return rc


class SceneLogs:
    """One log per scene at ``OUT/logs/scene_{seed:08d}.log``, all attempts appended. For a URL
    output the log is kept in a local staging directory and uploaded whole after each attempt
    (object stores cannot append)."""

    def __init__(self, out_root: str):
        self.root = storage.join(out_root, "logs")
        self.remote = storage.is_url(out_root)
        self.dir = pathlib.Path(tempfile.mkdtemp(prefix="kubric-logs-")) if self.remote \
            else pathlib.Path(self.root)
        self._fetched: set[int] = set()

    def prepare(self) -> None:
        if not self.remote:
            self.dir.mkdir(parents=True, exist_ok=True)

    def path(self, seed: int) -> pathlib.Path:
        """The local file to append to (a remote log is fetched first, once)."""
        local = self.dir / f"{scene_name(seed)}.log"
        if self.remote and seed not in self._fetched:
            self._fetched.add(seed)
            if storage.exists(self.location(seed)):
                local.write_bytes(storage.read_bytes(self.location(seed)))
        return local

    def location(self, seed: int) -> str:
        return storage.join(self.root, f"{scene_name(seed)}.log")

    def append(self, seed: int, text: str) -> None:
        with open(self.path(seed), "a") as fh:
            fh.write(text)
        self.publish(seed)

    def publish(self, seed: int) -> None:
        if self.remote:
            storage.write_bytes(self.location(seed), self.path(seed).read_bytes())


class Runner(abc.ABC):
    """What every runner shares: seeds, options, output root (path or URL), per-scene logs,
    resume (complete scenes skipped, stale work directories removed), the progress bar, the
    summary and SIGINT/SIGTERM handling. Subclasses implement :meth:`_execute`."""

    def __init__(self, recipe_spec: str, out_root, seeds: Sequence[int],
                 assignments: Sequence[str] = (), retries: int = 2,
                 timeout: float | None = None, progress: bool = True, resume: str = "same"):
        if retries < 0:
            raise ValueError(f"retries must be ≥ 0, got {retries}")
        if resume not in RESUME_MODES:
            raise ValueError(f"resume must be one of {RESUME_MODES}, got {resume!r}")
        self.resume = resume
        self.recipe_spec = recipe_spec
        root = storage.normalise(out_root)
        self.remote = storage.is_url(root)
        #: a ``pathlib.Path`` for local outputs, the URL string otherwise
        self.out_root = root if self.remote else pathlib.Path(root)
        self.seeds = list(dict.fromkeys(int(s) for s in seeds))
        self.assignments = list(assignments)
        self.retries = retries
        self.timeout = timeout
        self.progress = progress
        self.kill_after = 15.0  # seconds between terminate and kill on interruption
        self.logs = SceneLogs(self.out_root)
        self._stop = threading.Event()
        self._lock = threading.Lock()

    def scene_location(self, seed: int) -> str:
        return storage.join(self.out_root, scene_name(seed))

    def scene_complete(self, seed: int) -> bool:
        return is_complete(self.scene_location(seed))

    def command(self, seed: int) -> list[str]:
        return worker_command(self.recipe_spec, seed, self.out_root, self.assignments)

    def _record(self, seed: int, ok: bool, summary: RunSummary, bar) -> None:
        """Book a finished scene: done, or failed for good (after its last attempt)."""
        with self._lock:
            if ok:
                summary.done.append(seed)
                summary.failed.pop(seed, None)
            else:
                summary.failed[seed] = self.logs.path(seed)
            if bar:
                bar.update(1)
                bar.set_postfix(failed=len(summary.failed))

    def stop(self, *_args) -> None:
        """Start no new scene; subclasses also end the running ones."""
        self._stop.set()

    def _install_signals(self):
        if threading.current_thread() is not threading.main_thread():
            return {}
        previous = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, self.stop)
        return previous

    def cores(self) -> int | None:
        """The cores the scenes share (for the estimate); None when unknown (a cluster)."""
        return None

    def estimate(self, scenes: int) -> str | None:
        """The line announcing how long ``scenes`` scenes will take (kubric.pipeline.estimate),
        or None (a recipe or renderer without measured costs, unknown cores)."""
        if self.cores() is None:
            return None
        from kubric.pipeline.estimate import estimate_line
        from kubric.pipeline.recipe import get_recipe
        recipe = get_recipe(self.recipe_spec).from_assignments(self.assignments)
        return estimate_line(recipe.name, recipe.values, scenes, self.cores())

    @abc.abstractmethod
    def _execute(self, todo: list[int], summary: RunSummary, bar) -> None:
        """Run the scenes of ``todo`` (seeds), recording each result in ``summary``."""

    def run(self) -> RunSummary:
        """Run every scene not yet complete (one run per local output folder at a time)."""
        if self.remote:
            return self._run()
        pathlib.Path(self.out_root).mkdir(parents=True, exist_ok=True)
        with OutputLock(pathlib.Path(self.out_root) / LOCK_FILE, f"--out {str(self.out_root)!r}"):
            return self._run()

    def _run(self) -> RunSummary:
        start = time.time()
        summary = RunSummary(requested=len(self.seeds))
        if not self.remote:
            remove_stale(pathlib.Path(self.out_root))
        self.logs.prepare()
        complete = set(complete_scenes(self.out_root))
        if self.resume == "overwrite":
            removed = remove_requested(self.out_root, self.seeds, complete)
            complete -= set(removed)
            summary.replaced = len(removed)
        elif self.resume == "same" and complete:
            check_same_options(self.out_root, self.seeds, complete,
                               *run_options(self.recipe_spec, self.assignments))
        todo = []
        for seed in self.seeds:
            (summary.skipped if scene_name(seed) in complete else todo).append(seed)
        line = self.estimate(len(todo)) if todo and self.progress else None
        if line:
            print(line, flush=True)
        bar = None
        if self.progress and todo:
            from tqdm import tqdm
            bar = tqdm(total=len(todo), unit="scene", desc=self.recipe_spec.rsplit(":", 1)[-1],
                       dynamic_ncols=True)
            bar.set_postfix(failed=0)
        previous = self._install_signals()
        try:
            if todo:
                self._execute(todo, summary, bar)
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            if bar:
                bar.close()
        summary.interrupted = self._stop.is_set()
        if summary.interrupted:
            if not self.remote:
                time.sleep(0.2)
                remove_stale(pathlib.Path(self.out_root))
            # a worker stopped after its rename finished its scene: count what is on disk
            for seed in todo:
                if seed not in summary.done and self.scene_complete(seed):
                    summary.done.append(seed)
                    summary.failed.pop(seed, None)
        summary.seconds = time.time() - start
        return summary


class LocalRunner(Runner):
    """Run ``recipe_spec`` (see :func:`kubric.pipeline.recipe.recipe_spec`) for ``seeds`` on a
    pool of ``workers`` local processes.

    ``assignments`` are ``key=value`` option strings passed to every worker; validate them
    (build the recipe once) before calling :meth:`run`.

    Render threads: every worker renders with Blender's automatic count (all cores) unless
    ``KUBRIC_RENDER_THREADS`` is set: on the 2-core machine two scenes side by side with all
    threads each finished 1.15× faster than with one thread each (bench_scene_cost's throughput
    arms, docs/render-cost.md): a scene's single-threaded phases leave the other scene's threads
    the cores.
    """

    def __init__(self, recipe_spec: str, out_root, seeds: Sequence[int],
                 assignments: Sequence[str] = (), workers: int | None = None, retries: int = 2,
                 timeout: float | None = None, progress: bool = True, resume: str = "same"):
        if workers is not None and workers < 1:
            raise ValueError(f"workers must be ≥ 1, got {workers}")
        super().__init__(recipe_spec, out_root, seeds, assignments, retries, timeout, progress,
                         resume)
        self.workers = workers or usable_cores()
        self._procs: set[subprocess.Popen] = set()

    def cores(self) -> int:
        return usable_cores()

    # ------------------------------------------------------------------ one scene
    def _start(self, cmd, **kwargs):
        # Popen outside the lock: holding it serialised every worker start (measured with
        # benchmarks/bench_scale.py's stdlib worker, 4 workers: 35 % more scenes per second
        # without). A stop that comes meanwhile is seen after the registration below.
        if self._stop.is_set():
            return None
        proc = subprocess.Popen(cmd, **kwargs)
        with self._lock:
            self._procs.add(proc)
            stopped = self._stop.is_set()
        if stopped:
            proc.terminate()
        return proc

    def _attempt(self, seed: int, attempt: int) -> bool:
        # KUBRIC_DEBUG: the traceback of a failure goes into the scene's log
        env = dict(os.environ, **{PARENT_ENV: str(os.getpid()), "KUBRIC_DEBUG": "1"})
        try:
            rc = run_logged(self.command(seed), self.logs.path(seed), attempt, self.timeout, env,
                            start=self._start)
        finally:
            with self._lock:
                self._procs = {p for p in self._procs if p.poll() is None}
        self.logs.publish(seed)
        return rc == 0 and self.scene_complete(seed)

    def _run_one(self, seed: int, summary: RunSummary, bar) -> None:
        for attempt in range(1, self.retries + 2):
            if self._stop.is_set():
                return
            with self._lock:
                summary.attempts += 1
            if self._attempt(seed, attempt):
                self._record(seed, True, summary, bar)
                return
            if self._stop.is_set():
                return
        self._record(seed, False, summary, bar)

    # ------------------------------------------------------------------ signals
    def stop(self, *_args) -> None:
        """Start no new scene and terminate the running workers."""
        super().stop()
        with self._lock:
            procs = list(self._procs)
        for proc in procs:
            if proc.poll() is None:
                proc.terminate()
        killer = threading.Timer(self.kill_after, self._kill_all)
        killer.daemon = True
        killer.start()

    def _kill_all(self) -> None:
        with self._lock:
            procs = list(self._procs)
        for proc in procs:
            if proc.poll() is None:
                proc.kill()

    # ------------------------------------------------------------------ all scenes
    def _execute(self, todo: list[int], summary: RunSummary, bar) -> None:
        # ``workers`` threads take the next seed when free: one future per worker, not per
        # scene (submitting every scene at once cost the client ~2 KB per scene: 44 MB at 10³,
        # 63 MB at 10⁴ scenes in benchmarks/bench_scale.py)
        seeds = iter(todo)
        lock = threading.Lock()

        def serve() -> None:
            while not self._stop.is_set():
                with lock:
                    seed = next(seeds, None)
                if seed is None:
                    return
                self._run_one(seed, summary, bar)

        threads = min(self.workers, max(1, len(todo)))
        with ThreadPoolExecutor(max_workers=threads) as pool:
            futures = [pool.submit(serve) for _ in range(threads)]
            while any(not f.done() for f in futures):
                time.sleep(0.1)
            for f in futures:
                f.result()
