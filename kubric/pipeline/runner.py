"""The local runner: many scenes, one fresh ``python -m kubric worker`` process per scene.

* a pool of ``workers`` concurrent processes (default: the usable cores);
* a tqdm progress bar with ETA and the failure count;
* up to ``retries`` extra attempts per failed scene;
* one log per scene, kept, in ``OUT/logs/scene_{seed:08d}.log`` (all attempts appended);
* resume: complete scenes are skipped, stale work directories removed;
* SIGINT / SIGTERM: no new scenes start, running workers are terminated (they delete their work
  directories), and the summary says so. Even a ``kill -9`` of the runner leaves no directory that
  looks complete: only ``_SUCCESS`` marks a scene done, and the workers die with the runner
  (Linux parent-death signal).
"""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

from kubric.pipeline.worker import is_complete, remove_stale, scene_name

#: environment variable telling a worker to die with the runner that started it.
PARENT_ENV = "KUBRIC_RUNNER_PID"


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
        if self.interrupted:
            lines.append("interrupted: run the same command again to finish the remaining scenes")
        for seed, log in sorted(self.failed.items()):
            lines.append(f"  FAILED {scene_name(seed)}: {_last_line(log)}  (log: {log})")
        return "\n".join(lines)


def _last_line(log: pathlib.Path) -> str:
    try:
        lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines()
                 if ln.strip() and not ln.startswith("=== ")]
    except OSError:
        return "no log"
    return lines[-1][:200] if lines else "empty log"


def worker_command(recipe_spec: str, seed: int, out_root, assignments: Sequence[str]) -> list[str]:
    cmd = [sys.executable, "-m", "kubric", "worker", recipe_spec, "--seed", str(seed),
           "--out", str(out_root)]
    for a in assignments:
        cmd += ["--set", a]
    return cmd


class LocalRunner:
    """Run ``recipe_spec`` (see :func:`kubric.pipeline.recipe.recipe_spec`) for ``seeds``.

    ``assignments`` are ``key=value`` option strings passed to every worker; validate them
    (build the recipe once) before calling :meth:`run`.
    """

    def __init__(self, recipe_spec: str, out_root, seeds: Sequence[int],
                 assignments: Sequence[str] = (), workers: int | None = None, retries: int = 2,
                 timeout: float | None = None, progress: bool = True):
        if retries < 0:
            raise ValueError(f"retries must be ≥ 0, got {retries}")
        if workers is not None and workers < 1:
            raise ValueError(f"workers must be ≥ 1, got {workers}")
        self.recipe_spec = recipe_spec
        self.out_root = pathlib.Path(out_root).resolve()
        self.seeds = list(dict.fromkeys(int(s) for s in seeds))
        self.assignments = list(assignments)
        self.workers = workers or usable_cores()
        self.retries = retries
        self.timeout = timeout
        self.progress = progress
        self.kill_after = 15.0  # seconds between terminate and kill on interruption
        self.log_dir = self.out_root / "logs"
        self._stop = threading.Event()
        self._procs: set[subprocess.Popen] = set()
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ one scene
    def _attempt(self, seed: int, attempt: int) -> bool:
        log = self.log_dir / f"{scene_name(seed)}.log"
        cmd = worker_command(self.recipe_spec, seed, self.out_root, self.assignments)
        env = dict(os.environ, **{PARENT_ENV: str(os.getpid())})
        with open(log, "a") as fh:
            fh.write(f"=== attempt {attempt} at {time.strftime('%Y-%m-%d %H:%M:%S')}: "
                     f"{' '.join(cmd)}\n")
            fh.flush()
            with self._lock:
                if self._stop.is_set():
                    return False
                proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, env=env,
                                        stdin=subprocess.DEVNULL)
                self._procs.add(proc)
            try:
                rc = proc.wait(timeout=self.timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                rc = proc.wait()
                fh.write(f"=== timed out after {self.timeout} s\n")
            finally:
                with self._lock:
                    self._procs.discard(proc)
            fh.write(f"=== exit status {rc}\n")
        return rc == 0 and is_complete(self.out_root / scene_name(seed))

    def _run_one(self, seed: int, summary: RunSummary, bar) -> None:
        for attempt in range(1, self.retries + 2):
            if self._stop.is_set():
                return
            with self._lock:
                summary.attempts += 1
            if self._attempt(seed, attempt):
                with self._lock:
                    summary.done.append(seed)
                    summary.failed.pop(seed, None)
                    bar and bar.update(1)
                return
            if self._stop.is_set():
                return
            with self._lock:
                summary.failed[seed] = self.log_dir / f"{scene_name(seed)}.log"
        with self._lock:
            if bar:
                bar.update(1)
                bar.set_postfix(failed=len(summary.failed))

    # ------------------------------------------------------------------ signals
    def stop(self, *_args) -> None:
        """Start no new scene and terminate the running workers."""
        self._stop.set()
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

    def _install_signals(self):
        if threading.current_thread() is not threading.main_thread():
            return {}
        previous = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, self.stop)
        return previous

    # ------------------------------------------------------------------ all scenes
    def run(self) -> RunSummary:
        start = time.time()
        summary = RunSummary(requested=len(self.seeds))
        self.out_root.mkdir(parents=True, exist_ok=True)
        self.log_dir.mkdir(exist_ok=True)
        remove_stale(self.out_root)
        todo = []
        for seed in self.seeds:
            if is_complete(self.out_root / scene_name(seed)):
                summary.skipped.append(seed)
            else:
                todo.append(seed)
        bar = None
        if self.progress and todo:
            from tqdm import tqdm
            bar = tqdm(total=len(todo), unit="scene", desc=self.recipe_spec.rsplit(":", 1)[-1],
                       dynamic_ncols=True)
            bar.set_postfix(failed=0)
        previous = self._install_signals()
        try:
            with ThreadPoolExecutor(max_workers=min(self.workers, max(1, len(todo)))) as pool:
                futures = [pool.submit(self._run_one, s, summary, bar) for s in todo]
                while any(not f.done() for f in futures):
                    time.sleep(0.1)
                for f in futures:
                    f.result()
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            if bar:
                bar.close()
        summary.interrupted = self._stop.is_set()
        if summary.interrupted:
            time.sleep(0.2)
            remove_stale(self.out_root)
        summary.seconds = time.time() - start
        return summary
