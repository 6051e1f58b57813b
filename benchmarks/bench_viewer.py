"""`kubric view` serving a 100-scene folder: how fast the scene list appears and a frame switch
takes, over HTTP and in a headless chromium (when installed), against reading the same files
directly in the same run.

The folder: one MOVi-A scene rendered by `kubric worker` (``--size``², ``--frames`` frames, 4 spp)
copied 100 times as ``scene_{seed:08d}`` with the seed in each copy's metadata changed (the
viewer reads every copy's own files; their pixels are equal). The server runs as ``kubric view
DIR --port 0`` in its own process.

* list: ``GET /api/scenes`` cold (first request: 100 metadata.json parsed) and warm; baseline:
  ``read_json`` of the 100 metadata files in this process.
* frame switch: ``GET /api/frame/SCENE/LAYER/i.png`` for every frame of scenes not viewed before
  (cold: decode + colour map + PNG encode) and again (warm: LRU cache); baseline: ``read_frame``
  of the same file. Layers rgba, depth, forward_flow, segmentation.
* browser: page load until the 100-row table is drawn, and slider input until the new frame's
  image has loaded (cold frames).

Run: ``.venv/bin/python benchmarks/bench_viewer.py [--size 128] [--frames 12] [--scenes 100]``.
"""

from __future__ import annotations

import argparse
import http.client
import json
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import smoke_mode  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
LIST_BUDGET_S, FRAME_BUDGET_S = 1.0, 0.100


def make_folder(out: pathlib.Path, size: int, frames: int, scenes: int) -> pathlib.Path:
    from kubric.io.json_io import read_json, write_json
    render = out / "render"
    cmd = [sys.executable, "-m", "kubric", "worker", "movi_a", "--seed", "0", "--out", str(render)]
    for option in (f"resolution={size}", f"frame_end={frames}", "samples=4", "denoise=false",
                   f"tracks={smoke_mode.size(64, 4)}"):
        cmd += ["--set", option]
    start = time.perf_counter()
    subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True)
    print(f"rendered one {size}² MOVi-A scene, {frames} frames: {time.perf_counter() - start:.1f} s")
    folder = out / "dataset"
    for seed in range(scenes):
        target = folder / f"scene_{seed:08d}"
        shutil.copytree(render / "scene_00000000", target)
        meta = read_json(target / "metadata.json")
        meta["flags"]["seed"] = meta["metadata"]["seed"] = seed
        write_json(meta, target / "metadata.json")
    return folder


def get(port: int, target: str) -> tuple[float, bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    start = time.perf_counter()
    conn.request("GET", target)
    response = conn.getresponse()
    body = response.read()
    elapsed = time.perf_counter() - start
    conn.close()
    if response.status != 200:
        raise RuntimeError(f"{target}: HTTP {response.status}: {body[:200]!r}")
    return elapsed, body


def ms(seconds: float) -> str:
    return f"{seconds * 1000:.1f} ms"


def verdict(value: float, budget: float) -> str:
    return "within" if value < budget else "OVER"


def http_numbers(folder: pathlib.Path, port: int, frames: int) -> dict:
    from kubric.io.json_io import read_json
    from kubric.io.layers import read_frame
    out = {}
    start = time.perf_counter()
    for d in sorted(folder.iterdir()):
        read_json(d / "metadata.json")
    out["list_baseline"] = time.perf_counter() - start
    out["list_cold"], body = get(port, "/api/scenes")
    assert len(json.loads(body)["scenes"]) == len(list(folder.iterdir()))
    out["list_warm"] = min(get(port, "/api/scenes")[0] for _ in range(5))
    for layer in ("rgba", "depth", "forward_flow", "segmentation"):
        cold, warm, direct = [], [], []
        for scene in ("scene_00000010", "scene_00000011", "scene_00000012"):
            get(port, f"/api/scene/{scene}")  # what the page asks first
            for i in range(frames):
                cold.append(get(port, f"/api/frame/{scene}/{layer}/{i}.png")[0])
                warm.append(get(port, f"/api/frame/{scene}/{layer}/{i}.png")[0])
                start = time.perf_counter()
                read_frame(folder / scene, layer, i)
                direct.append(time.perf_counter() - start)
        out[layer] = (statistics.median(cold), max(cold), statistics.median(warm),
                      statistics.median(direct))
    probes = [get(port, f"/api/probe/scene_00000020/{i}?row=5&col=7")[0] for i in range(frames)]
    out["probe_cold"] = statistics.median(probes)
    return out


def browser_numbers(port: int, frames: int, rows: int) -> dict | None:
    chromium, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if not chromium or not driver:
        print("browser: chromium / chromedriver not installed (make browser): browser numbers "
              "left out")
        return None
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1000"):
        options.add_argument(arg)
    browser = webdriver.Chrome(options=options, service=Service(driver))
    try:
        url = f"http://127.0.0.1:{port}/"
        loads = []
        for _ in range(3):
            browser.get("about:blank")
            start = time.perf_counter()
            browser.get(url)
            while len(browser.find_elements("css selector", "tr.scene-row")) < rows:
                time.sleep(0.002)
            loads.append(time.perf_counter() - start)
        switches = []
        for scene in ("scene_00000030", "scene_00000031"):
            browser.get(url + f"#/scene/{scene}")
            browser.refresh()
            browser.execute_script("window.__t = null;")
            while not browser.execute_script(
                    "const i = document.getElementById('main-img'); return i && i.complete && "
                    "i.naturalWidth > 0"):
                time.sleep(0.005)
            for layer in ("depth", "forward_flow"):  # frames nobody requested yet: cold
                # back to frame 0 first: each switch below then asks for a new picture (the
                # viewer does not reload the picture it already shows, so no load event)
                browser.execute_script(
                    "const f = document.getElementById('frame-slider'); f.value = 0;"
                    "f.dispatchEvent(new Event('input'));"
                    "const s = document.getElementById('layer-select'); s.value = arguments[0];"
                    "s.dispatchEvent(new Event('change'));", layer)
                while not browser.execute_script(
                        "const i = document.getElementById('main-img'); return i.complete && "
                        "i.src.includes('/' + arguments[0] + '/')", layer):
                    time.sleep(0.005)
                for i in range(1, frames):
                    took = browser.execute_async_script("""
                        const done = arguments[1], img = document.getElementById('main-img');
                        const start = performance.now();
                        img.addEventListener('load', () => done(performance.now() - start),
                                             { once: true });
                        const s = document.getElementById('frame-slider');
                        s.value = arguments[0]; s.dispatchEvent(new Event('input'));""", i)
                    switches.append(took / 1000)
        return {"page_load": statistics.median(loads), "switch_median": statistics.median(switches),
                "switch_max": max(switches), "switches": len(switches)}
    finally:
        browser.quit()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=smoke_mode.size(128, 16))
    parser.add_argument("--frames", type=int, default=smoke_mode.size(12, 2))
    parser.add_argument("--scenes", type=int, default=smoke_mode.size(100, 32))  # 32: it asks for scene 31
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = make_folder(pathlib.Path(tmp), args.size, args.frames, args.scenes)
        server = subprocess.Popen([sys.executable, "-m", "kubric", "view", str(folder),
                                   "--port", "0"], cwd=ROOT, stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, text=True)
        try:
            line = server.stdout.readline()
            port = int(line.rsplit(":", 1)[1].split("/")[0])
            numbers = http_numbers(folder, port, args.frames)
            in_browser = browser_numbers(port, args.frames, min(100, args.scenes))  # rows shown
        finally:
            server.terminate()
            server.wait(timeout=10)
    print(f"\n{args.scenes} scenes of {args.size}², {args.frames} frames; server: kubric view in "
          "its own process")
    print(f"scene list  HTTP cold {ms(numbers['list_cold'])} ({verdict(numbers['list_cold'], LIST_BUDGET_S)} "
          f"the {LIST_BUDGET_S:.0f} s budget), warm {ms(numbers['list_warm'])}; baseline read_json "
          f"of the metadata files {ms(numbers['list_baseline'])} (cold HTTP / baseline "
          f"{numbers['list_cold'] / numbers['list_baseline']:.2f}×)")
    print("frame switch over HTTP (median cold / max cold / median warm; baseline read_frame):")
    for layer in ("rgba", "depth", "forward_flow", "segmentation"):
        cold, worst, warm, direct = numbers[layer]
        print(f"  {layer:13s} {ms(cold):>9s} / {ms(worst):>9s} / {ms(warm):>8s}; read_frame "
              f"{ms(direct)} (cold / read_frame {cold / direct:.1f}×)  {verdict(worst, FRAME_BUDGET_S)} "
              f"the {FRAME_BUDGET_S * 1000:.0f} ms budget")
    print(f"pixel probe (cold frames) median {ms(numbers['probe_cold'])}")
    if in_browser:
        print(f"browser: page load → 100-row table {ms(in_browser['page_load'])} "
              f"({verdict(in_browser['page_load'], LIST_BUDGET_S)} budget); frame switch (slider → "
              f"new image loaded, {in_browser['switches']} cold switches) median "
              f"{ms(in_browser['switch_median'])}, max {ms(in_browser['switch_max'])} "
              f"({verdict(in_browser['switch_max'], FRAME_BUDGET_S)} budget)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
