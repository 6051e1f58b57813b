"""`kubric generate --cluster` / `--out URL`: bad input is one clear line and starts nothing;
the Slurm job script dask-jobqueue would submit; the job-array examples in deploy/ run
`kubric worker --index` for real."""

import os
import pathlib
import re
import shlex
import subprocess
import sys

import pytest
import yaml
from dask_helpers import free_port, processes, slurm_missing, start_slurm

from kubric.pipeline.worker import is_complete

ROOT = pathlib.Path(__file__).resolve().parents[1]
FAKE = f"{ROOT / 'tests' / 'fake_recipes.py'}:Fake"


def kubric(*args, env=None, timeout=120, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "kubric", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)


def assert_one_line(proc, *fragments):
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kubric generate: error:"), proc.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


@pytest.mark.slow
def test_bad_cluster_and_output_are_one_line_and_start_nothing(tmp_path):
    out = tmp_path / "ds"
    gen = ["generate", FAKE, "--out", str(out), "--scenes", "2", "--no-progress"]
    port = free_port()  # nothing listens there
    proc = kubric(*gen, "--cluster", f"tcp://127.0.0.1:{port}", "--connect-timeout", "2")
    assert_one_line(proc, f"no Dask scheduler answered at tcp://127.0.0.1:{port} within 2 s")
    assert not out.exists()
    assert_one_line(kubric(*gen, "--cluster", "yarn"), "--cluster 'yarn': expected local, slurm")
    assert_one_line(kubric(*gen, "--cluster", "tcp://host"), "tcp://HOST:PORT")
    assert_one_line(kubric(*gen, "--cluster", "local", "--threads-per-scene", "0"),
                    "--threads-per-scene must be ≥ 1, got 0")
    # flags where they mean nothing are refused, not ignored
    assert_one_line(kubric(*gen, "--threads-per-scene", "2"), "--threads-per-scene needs --cluster")
    assert_one_line(kubric(*gen, "--cluster", "local", "--queue", "gpu"),
                    "--queue applies to --cluster slurm only")
    assert_one_line(kubric(*gen, "--cluster", f"tcp://127.0.0.1:{port}", "--workers", "2"),
                    "--workers does not apply to a running scheduler")
    # --cluster slurm without sbatch on the PATH
    env = dict(os.environ, PATH=str(tmp_path / "empty-bin"))
    proc = kubric(*gen, "--cluster", "slurm", env=env)
    assert_one_line(proc, "sbatch is not on the PATH")
    # malformed or unwritable outputs
    (tmp_path / "file").write_text("x")
    for bad, fragment in ((str(tmp_path / "file" / "ds"), "is a file, not a directory"),
                          ("nosuch://bucket/run", "unknown storage protocol 'nosuch'"),
                          ("s3://", "names no bucket"),
                          ("memory://run", "private to one process")):
        proc = kubric("generate", FAKE, "--out", bad, "--scenes", "2", "--cluster", "local")
        assert_one_line(proc, fragment)
    assert "Dask dashboard" not in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_slurm_job_script_contents():
    proc = kubric("generate", FAKE, "--out", "/tmp/x", "--scenes", "2", "--cluster", "slurm",
                  "--print-job-script", "--cores-per-job", "8", "--threads-per-scene", "4",
                  "--memory", "16GB", "--walltime", "02:30:00", "--queue", "render",
                  "--job-directive=--gres=gpu:1", "--job-directive=--account=vision")
    assert proc.returncode == 0, proc.stderr
    script = proc.stdout
    directives = re.findall(r"^#SBATCH (.*)$", script, re.M)
    assert "-p render" in directives and "-t 02:30:00" in directives
    assert "--cpus-per-task=8" in directives
    assert "--mem=15G" in directives  # dask-jobqueue: 16 GB = 14.9 GiB, rounded up
    assert "--gres=gpu:1" in directives and "--account=vision" in directives
    command = shlex.split(script.strip().splitlines()[-1])
    assert command[0] == sys.executable and "distributed.cli.dask_worker" in command
    # 8 cores / 4 threads per scene = 2 worker processes, each one scene slot
    assert command[command.index("--nworkers") + 1] == "2"
    assert command[command.index("--resources") + 1] == "scene=1"
    assert command[command.index("--nthreads") + 1] == "4"
    proc = kubric("generate", FAKE, "--out", "/tmp/x", "--scenes", "2", "--cluster", "slurm",
                  "--print-job-script", "--cores-per-job", "2", "--threads-per-scene", "4")
    assert proc.returncode == 2 and "--cores-per-job 2 is less than --threads-per-scene 4" \
        in proc.stderr


def test_slurm_array_script_runs_worker_index(tmp_path):
    script = ROOT / "deploy" / "slurm_array.sbatch"
    text = script.read_text()
    directives = re.findall(r"^#SBATCH (\S+)", text, re.M)
    assert any(d.startswith("--array=") for d in directives)
    assert "kubric worker" in text and "--index" in text
    env = dict(os.environ, SLURM_ARRAY_TASK_ID="3", SLURM_CPUS_PER_TASK="2",
               KUBRIC_RECIPE=FAKE, KUBRIC_OUT=str(tmp_path / "ds"), KUBRIC_FIRST_SEED="10",
               KUBRIC_PYTHON=sys.executable)
    for _ in range(2):  # the second run finds the scene complete
        proc = subprocess.run(["bash", str(script), "--set", "frames=2"], env=env, cwd=ROOT,
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.startswith("skipped:")
    scene = tmp_path / "ds" / "scene_00000013"  # first seed 10 + index 3
    assert is_complete(scene) and len(list(scene.glob("rgba_*.png"))) == 2
    assert sorted(p.name for p in (tmp_path / "ds").iterdir()) == ["scene_00000013"]
    env.pop("SLURM_ARRAY_TASK_ID")
    proc = subprocess.run(["bash", str(script)], env=env, cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode != 0 and "not a Slurm array task" in proc.stderr


def test_kubernetes_indexed_job_runs_worker_index(tmp_path):
    job = yaml.safe_load((ROOT / "deploy" / "k8s_indexed_job.yaml").read_text())
    spec = job["spec"]
    assert job["kind"] == "Job" and spec["completionMode"] == "Indexed"
    assert spec["completions"] >= spec["parallelism"] >= 1
    assert spec["template"]["spec"]["restartPolicy"] == "Never"
    (container,) = spec["template"]["spec"]["containers"]
    env = {e["name"]: e for e in container["env"]}
    assert env["KUBRIC_INDEX"]["valueFrom"]["fieldRef"]["fieldPath"] == \
        "metadata.annotations['batch.kubernetes.io/job-completion-index']"
    command = container["command"]
    assert command[:4] == ["python", "-m", "kubric", "worker"]
    assert command[command.index("--index") + 1] == "$(KUBRIC_INDEX)"
    # run the container's command as Kubernetes would for index 4 (recipe and output swapped
    # for the test recipe and a local folder)
    run = [sys.executable if a == "python" else a.replace("$(KUBRIC_INDEX)", "4")
           for a in command]
    run[4] = FAKE
    run[run.index("--out") + 1] = str(tmp_path / "ds")
    run = [a for a in run if a != "resolution=256"]
    run.remove("--set")
    proc = subprocess.run(run, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert is_complete(tmp_path / "ds" / "scene_00000004")


@pytest.mark.slow
@pytest.mark.skipif(bool(slurm_missing()), reason=f"no single-node Slurm here (missing "
                    f"{slurm_missing()}; Debian: apt-get install slurmctld slurmd slurm-client "
                    f"munge)")
def test_cluster_slurm_and_job_array_on_a_single_node_slurm(tmp_path):
    with processes() as procs:
        env = start_slurm(procs, tmp_path / "slurm")
        # --cluster slurm: dask-jobqueue submits a worker job, the scenes run in it
        out = tmp_path / "ds"
        proc = subprocess.run(
            [sys.executable, "-m", "kubric", "generate", FAKE, "--out", str(out), "--scenes", "4",
             "--cluster", "slurm", "--jobs", "1", "--cores-per-job", "1", "--memory", "1GB",
             "--walltime", "00:10:00", "--queue", "kubric", "--dashboard-address", ":0",
             "--no-progress"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert "4 generated, 0 already complete, 0 failed of 4 scenes" in proc.stdout
        assert all(is_complete(out / f"scene_{s:08d}") for s in range(4))
        # the job array script, submitted with sbatch: one scene per array index
        array_out = tmp_path / "array"
        sbatch = subprocess.run(
            ["sbatch", "--parsable", "--wait", "--array=0-2", "--cpus-per-task=1", "--mem=500M",
             f"--output={tmp_path}/array-%A_%a.log", str(ROOT / "deploy" / "slurm_array.sbatch"),
             "--set", "frames=2"], cwd=ROOT, capture_output=True, text=True, timeout=300,
            env=dict(env, KUBRIC_RECIPE=FAKE, KUBRIC_OUT=str(array_out), KUBRIC_FIRST_SEED="5",
                     KUBRIC_PYTHON=sys.executable))
        assert sbatch.returncode == 0, sbatch.stdout + sbatch.stderr
        assert sorted(p.name for p in array_out.iterdir()) == \
            [f"scene_{s:08d}" for s in (5, 6, 7)]
        assert all(is_complete(p) for p in array_out.iterdir())
