"use strict";
// One scene: main layer + overlays with a frame scrubber and play/pause, a hover readout of what
// the files hold at a pixel, instance details on click, a 3D view and the reproducing command;
// a camera rig's cameras side by side under the stage (rigview.js).
// While a frame's picture is on its way the stage says so ("loading …"); the address bar links to
// the view on screen (deeplink.js). Pictures are scaled by whole factors without smoothing
// (style.css: image-rendering pixelated), so labels and ids never blend.
// The layers' names and how they are drawn come from the server (scene.layers: label, kind,
// adjustable_range and its first range), which derives them from kubric.io.layers.
const KVScene = (function () {
  let s = null;  // the open scene's state

  function stop() {
    if (s && s.timer) clearInterval(s.timer);
    s = null;
  }

  function numFrames(scene) {
    return scene.summary.num_frames || (scene.metadata.metadata || {}).num_frames || 1;
  }

  function layerInfo(layer) {
    return (s.scene.layers || {})[layer] || { label: layer, adjustable_range: false };
  }

  function mainUrl() {
    const ranged = layerInfo(s.layer).adjustable_range;
    return KV.frameUrl(s.name, s.layer, s.frame, ranged ? s.lo.value : undefined,
      ranged ? s.hi.value : undefined);
  }

  function showRange() {  // a depth-like layer: its [lo, hi] box, at the layer's own range
    const info = layerInfo(s.layer), range = info.range || [0, 10];
    s.depthBox.style.display = info.adjustable_range ? "" : "none";
    if (info.adjustable_range) { s.lo.value = range[0].toFixed(2); s.hi.value = range[1].toFixed(2); }
  }

  function setFrame(frame) {
    s.frame = ((frame % s.T) + s.T) % s.T;
    s.slider.value = s.frame;
    const start = (s.scene.metadata.metadata || {}).frame_start;
    s.frameLabel.textContent = `frame ${s.frame} / ${s.T - 1}` +
      (start !== undefined ? ` (scene frame ${start + s.frame})` : "");
    loadMain(mainUrl());
    s.outline.src = KV.frameUrl(s.name, "outline", s.frame);
    if (s.hasSegmentation) s.fill.src = KV.frameUrl(s.name, "fill", s.frame);
    drawOverlay();
    if (s.view3d) s.view3d.setFrame(s.frame);
    if (s.rig) s.rig.show(s.frame, s.layer);
    if (s.selected !== null) showInstance(s.selected);
    if (s.lastProbe) probe(s.lastProbe[0], s.lastProbe[1]);
  }

  // the main picture: the stage shows "loading …" until it arrives (or fails)
  function loadMain(url) {
    if (s.img.getAttribute("src") === url && s.img.complete) return;
    const info = layerInfo(s.layer);
    s.loading.textContent = `loading ${info.label || s.layer}, frame ${s.frame}…`;
    s.stage.classList.add("loading");
    s.img.src = url;
  }

  function viewState() {
    const overlays = KVLink.OVERLAYS.filter((o) => s.boxes[o].checked);
    return { frame: s.frame, layer: s.layer, overlays, opacity: Number(s.opacity.value) };
  }

  function updateLink() {
    const hash = KVLink.format(s.name, viewState());
    if (location.hash !== hash) history.replaceState(null, "", hash);
    s.link.setAttribute("href", hash);
  }

  // a deep link's view (deeplink.js), each value checked against the scene; what cannot be
  // shown is named in a card and left at the scene's default
  function applyLink(view, layers) {
    const refused = [];
    if (view.layer !== undefined) {
      if (layers.includes(view.layer)) { s.layer = view.layer; s.select.value = view.layer; }
      else refused.push(`layer ${JSON.stringify(view.layer)} (this scene: ${layers.join(", ")})`);
    }
    // no overlays in the link: the segmentation outlines, so a scene opens with its objects marked
    if (view.overlays === undefined && !s.boxes.outline.disabled) s.boxes.outline.checked = true;
    for (const o of view.overlays || []) {
      if (s.boxes[o] && !s.boxes[o].disabled) s.boxes[o].checked = true;
      else refused.push(`overlay ${JSON.stringify(o)} (available: ${KVLink.OVERLAYS.filter((x) => !s.boxes[x].disabled).join(", ")})`);
    }
    if (view.opacity !== undefined) {
      const p = Number(view.opacity);
      if (view.opacity !== "" && Number.isInteger(p) && p >= 0 && p <= 100) s.opacity.value = p;
      else refused.push(`opacity ${JSON.stringify(view.opacity)} (a whole number 0..100)`);
    }
    let frame = 0;
    if (view.frame !== undefined) {
      const f = Number(view.frame);
      if (view.frame !== "" && Number.isInteger(f) && f >= 0 && f < s.T) frame = f;
      else refused.push(`frame ${JSON.stringify(view.frame)} (0..${s.T - 1})`);
    }
    for (const key of Object.keys(view)) {
      if (!["frame", "layer", "overlays", "opacity"].includes(key)) refused.push(`parameter ${JSON.stringify(key)} (allowed: frame, layer, overlays, opacity)`);
    }
    if (refused.length) s.linkError.replaceChildren(KV.errorCard("this link asks for what the scene cannot show", refused.join("; ")));
    return frame;
  }

  function drawOverlay() {
    const ctx = s.canvas.getContext("2d");
    ctx.clearRect(0, 0, s.canvas.width, s.canvas.height);
    const k = s.scale, opacity = s.opacity.value / 100;
    s.outline.style.opacity = s.showOutline.checked ? opacity : 0;
    s.fill.style.opacity = s.boxes.fill.checked ? opacity : 0;
    s.canvas.style.opacity = opacity;
    updateLink();
    if (s.showBoxes.checked) {
      (s.scene.metadata.instances || []).forEach((inst, i) => {
        const at = (inst.bbox_frames || []).indexOf(s.frame);
        if (at < 0) return;
        const [ymin, xmin, ymax, xmax] = inst.bboxes[at];
        ctx.strokeStyle = KV.rgb(s.scene.palette[i + 1]);
        ctx.lineWidth = s.selected === i ? 3 : 1.5;
        ctx.strokeRect(xmin * s.W * k, ymin * s.H * k, (xmax - xmin) * s.W * k, (ymax - ymin) * s.H * k);
        ctx.fillStyle = ctx.strokeStyle; ctx.font = "12px sans-serif";
        ctx.fillText(String(i), xmin * s.W * k + 2, ymin * s.H * k + 12);
      });
    }
    if (s.showKeypoints.checked) drawKeypoints(ctx, k);
    if (s.showTracks.checked && s.tracks) {
      const tr = s.tracks, trail = 8;
      tr.target_points.forEach((points, n) => {
        const hue = (n * 0.618033988749895) % 1;
        ctx.strokeStyle = ctx.fillStyle = `hsl(${Math.round(hue * 360)}, 85%, 60%)`;
        ctx.lineWidth = 1.5;
        for (let t = Math.max(0, s.frame - trail); t < s.frame; t++) {
          if (tr.occluded[n][t] || tr.occluded[n][t + 1]) continue;
          ctx.beginPath(); ctx.moveTo(points[t][0] * k, points[t][1] * k);
          ctx.lineTo(points[t + 1][0] * k, points[t + 1][1] * k); ctx.stroke();
        }
        const [x, y] = points[s.frame];
        ctx.beginPath(); ctx.arc(x * k, y * k, Math.max(3, k / 3), 0, 2 * Math.PI);
        if (tr.occluded[n][s.frame]) ctx.stroke(); else ctx.fill();
      });
    }
  }

  // People's keypoints (docs/characters.md): COCO's skeleton between keypoints in the image
  // (solid when both ends are visible, dashed when one is occluded), dots filled when visible.
  function drawKeypoints(ctx, k) {
    (s.scene.metadata.instances || []).forEach((inst, i) => {
      if (!inst.keypoints_2d) return;
      const kp = inst.keypoints_2d[s.frame], vis = inst.keypoints_visibility[s.frame];
      ctx.strokeStyle = ctx.fillStyle = KV.rgb(s.scene.palette[i + 1]);
      ctx.lineWidth = s.selected === i ? 3 : 2;
      (inst.keypoint_skeleton || []).forEach(([a, b]) => {
        if (!vis[a - 1] || !vis[b - 1]) return;
        ctx.setLineDash(vis[a - 1] === 2 && vis[b - 1] === 2 ? [] : [4, 3]);
        ctx.beginPath(); ctx.moveTo(kp[a - 1][0] * k, kp[a - 1][1] * k);
        ctx.lineTo(kp[b - 1][0] * k, kp[b - 1][1] * k); ctx.stroke();
      });
      ctx.setLineDash([]);
      kp.forEach(([x, y], j) => {
        if (!vis[j]) return;
        ctx.beginPath(); ctx.arc(x * k, y * k, Math.max(3, k / 3), 0, 2 * Math.PI);
        if (vis[j] === 2) ctx.fill(); else ctx.stroke();
      });
    });
  }

  async function probe(col, row) {
    s.lastProbe = [col, row];
    if (s.probing) { s.pendingProbe = true; return; }
    s.probing = true;
    const frame = s.frame, name = s.name;
    try {
      const p = await KV.getJSON(`/api/probe/${encodeURIComponent(name)}/${frame}?row=${row}&col=${col}`);
      if (s && s.name === name) showReadout(p);
    } catch (err) {
      if (s) s.readout.replaceChildren(KV.errorCard("probe", err.message));
    } finally {
      if (s) {
        s.probing = false;
        if (s.pendingProbe) { s.pendingProbe = false; probe(s.lastProbe[0], s.lastProbe[1]); }
      }
    }
  }

  function showReadout(p) {
    const item = (label, id, value) => [KV.el("span", {}, label), KV.el("span", { id }, value)];
    const inst = p.instance === null || p.instance === undefined ? "background" : String(p.instance);
    const flow = (f) => (f ? `Δrow ${f[0].toFixed(2)}, Δcol ${f[1].toFixed(2)} px` : "–");
    s.readout.replaceChildren(KV.el("div", { class: "kv", "data-frame": p.frame },
      item("pixel", "readout-pixel", `row ${p.row}, col ${p.col}`),
      item("instance", "readout-instance", inst),
      item("asset", "readout-asset", p.asset_id || "–"),
      item("depth", "readout-depth", p.background ? "background" :
        p.depth === undefined ? "–" : p.depth.toFixed(4) + " m"),
      item("forward flow", "readout-flow", flow(p.forward_flow)),
      item("backward flow", "readout-bflow", flow(p.backward_flow)),
      item("3D point", "readout-point", p.point ? KV.fmt(p.point) + " m" : "–"),
      item("RGBA", "readout-rgba", p.rgba ? KV.fmt(p.rgba) : "–")));
  }

  function pixelAt(event) {
    const rect = s.img.getBoundingClientRect();
    const col = Math.floor((event.clientX - rect.left) / rect.width * s.W);
    const row = Math.floor((event.clientY - rect.top) / rect.height * s.H);
    return col >= 0 && row >= 0 && col < s.W && row < s.H ? [col, row] : null;
  }

  function showInstance(k) {
    s.selected = k;
    const inst = (s.scene.metadata.instances || [])[k];
    if (!inst) { s.instancePanel.replaceChildren(KV.el("p", { class: "muted" }, "click an object")); return; }
    const colour = KV.rgb(s.scene.palette[k + 1]);
    const keys = ["asset_id", "shape", "size_label", "material", "color_label", "category", "mass",
      "friction", "restitution", "scale", "is_dynamic"];
    const rows = [];
    for (const key of keys) if (inst[key] !== undefined) rows.push(KV.el("span", {}, key), KV.el("span", {}, KV.fmt(inst[key])));
    const t = s.frame;
    for (const [key, label] of [["positions", "position (m)"], ["velocities", "velocity (m/s)"], ["image_positions", "image position"]]) {
      if (inst[key] && inst[key][t]) rows.push(KV.el("span", {}, `${label} @${t}`), KV.el("span", {}, KV.fmt(inst[key][t])));
    }
    const vis = inst.visibility || [];
    rows.push(KV.el("span", {}, `visible px @${t}`), KV.el("span", { id: "instance-visibility" }, KV.fmt(vis[t])));
    const plot = KV.el("canvas", { class: "plot", width: 300, height: 90, id: "visibility-plot" });
    const collisions = ((s.scene.events || {}).collisions || []).filter((c) => c.instances.includes(k));
    const collisionList = KV.el("div", { class: "scroll" }, collisions.length ? KV.el("table", {},
      KV.el("tr", {}, KV.el("th", {}, "frame"), KV.el("th", {}, "with"), KV.el("th", {}, "force (N)")),
      collisions.map((c) => {
        const other = c.instances[0] === k ? c.instances[1] : c.instances[0];
        return KV.el("tr", {}, KV.el("td", {}, c.frame.toFixed(2)),
          KV.el("td", {}, other < 0 ? "floor / dome" : "instance " + other), KV.el("td", {}, KV.fmt(c.force, 2)));
      })) : KV.el("span", { class: "muted" }, "no collisions"));
    const trajectory = KV.el("div", { class: "scroll" }, KV.el("table", {},
      KV.el("tr", {}, KV.el("th", {}, "frame"), KV.el("th", {}, "position (m)"), KV.el("th", {}, "visible px")),
      (inst.positions || []).map((p, i) => KV.el("tr", { style: i === t ? "color:#fff;font-weight:600" : "" },
        KV.el("td", {}, i), KV.el("td", {}, KV.fmt(p, 2)), KV.el("td", {}, KV.fmt(vis[i]))))));
    s.instancePanel.replaceChildren(
      KV.el("h3", { style: `color:${colour}` }, `instance ${k}`),
      KV.el("div", { class: "kv", id: "instance-details", "data-instance": k }, rows),
      KV.el("h3", { style: "margin-top:8px" }, "visibility over time"), plot,
      KV.el("h3", { style: "margin-top:8px" }, `collisions (${collisions.length})`), collisionList,
      KV.el("h3", { style: "margin-top:8px" }, "trajectory"), trajectory);
    KVPlot.visibility(plot, vis, t, colour);
    if (s.view3d) s.view3d.select(k);
    drawOverlay();
  }

  function buildControls(scene) {
    // a layer another one before it shows under the same label (rgb beside rgba) is listed once
    const labels = scene.summary.layers.map((l) => layerInfo(l).label);
    const layers = scene.summary.layers.filter((l, i) => labels.indexOf(labels[i]) === i);
    s.layer = layers[0];
    s.layers = layers;
    const select = s.select = KV.el("select", { id: "layer-select", onchange: (e) => {
      s.layer = e.target.value;
      showRange();
      setFrame(s.frame);
    } }, layers.map((l) => KV.el("option", { value: l }, layerInfo(l).label)));
    s.lo = KV.el("input", { type: "number", step: "0.1", id: "depth-lo", onchange: () => setFrame(s.frame) });
    s.hi = KV.el("input", { type: "number", step: "0.1", id: "depth-hi", onchange: () => setFrame(s.frame) });
    s.depthBox = KV.el("span", { style: "display:none" }, "range ", s.lo, " – ", s.hi);
    showRange();
    const check = (id, label, disabled) => {
      const box = KV.el("input", { type: "checkbox", id, disabled, onchange: drawOverlay });
      return [box, KV.el("label", { for: id }, label)];
    };
    s.hasSegmentation = scene.summary.layers.includes("segmentation");
    const [outlineBox, outlineLabel] = check("overlay-outline", "segmentation outlines", !s.hasSegmentation);
    const [fillBox, fillLabel] = check("overlay-fill", "segmentation (filled)", !s.hasSegmentation);
    const [boxesBox, boxesLabel] = check("overlay-boxes", "2D boxes", false);
    const [tracksBox, tracksLabel] = check("overlay-tracks", "point tracks", !scene.summary.has_tracks);
    const hasKeypoints = (scene.metadata.instances || []).some((inst) => inst.keypoints_2d);
    const [keypointsBox, keypointsLabel] = check("overlay-keypoints", "keypoints", !hasKeypoints);
    s.showOutline = outlineBox; s.showBoxes = boxesBox; s.showTracks = tracksBox;
    s.showKeypoints = keypointsBox;
    s.boxes = { outline: outlineBox, fill: fillBox, boxes: boxesBox, tracks: tracksBox, keypoints: keypointsBox };
    s.opacity = KV.el("input", { type: "range", min: 0, max: 100, value: 90, id: "overlay-opacity", oninput: drawOverlay });
    s.slider = KV.el("input", { type: "range", min: 0, max: s.T - 1, value: 0, id: "frame-slider",
      oninput: (e) => setFrame(Number(e.target.value)) });
    s.frameLabel = KV.el("span", { id: "frame-label" }, "");
    s.link = KV.el("a", { id: "deep-link", title: "a link that reopens this view" }, "link to this view");
    const play = KV.el("button", { id: "play", onclick: () => {
      if (s.timer) { clearInterval(s.timer); s.timer = null; play.textContent = "▶ play"; return; }
      const rate = (scene.metadata.metadata || {}).frame_rate || 12;
      s.timer = setInterval(() => setFrame(s.frame + 1), 1000 / rate);
      play.textContent = "❚❚ pause";
    } }, "▶ play");
    return [
      KV.el("div", { class: "toolbar" }, "layer ", select, s.depthBox),
      KV.el("div", { class: "toolbar" }, "overlays ", fillBox, fillLabel, outlineBox, outlineLabel, boxesBox, boxesLabel,
        tracksBox, tracksLabel, keypointsBox, keypointsLabel, " opacity ", s.opacity),
      KV.el("div", { class: "toolbar" }, play, s.slider, s.frameLabel, s.link),
    ];
  }

  async function show(app, name, view) {
    document.getElementById("crumb").textContent = "/ " + name;
    app.replaceChildren(KV.el("p", { class: "muted" }, "loading " + name + "…"));
    let scene;
    try {
      scene = await KV.getJSON(KV.sceneUrl(name));
    } catch (err) {
      app.replaceChildren(KV.errorCard("cannot show " + name, err.message), KV.el("a", { href: "#/" }, "← all scenes"));
      return;
    }
    const [W, H] = scene.summary.resolution || scene.metadata.metadata.resolution;
    const scale = Math.max(1, Math.floor(Math.min(640 / W, 480 / H)));
    s = { name, scene, W, H, scale, T: numFrames(scene), frame: 0, selected: null, timer: null };
    s.img = KV.el("img", { id: "main-img", width: W * scale, height: H * scale, alt: "frame" });
    s.fill = KV.el("img", { id: "fill-img", width: W * scale, height: H * scale, alt: "" });
    s.outline = KV.el("img", { id: "outline-img", width: W * scale, height: H * scale, alt: "" });
    s.canvas = KV.el("canvas", { id: "overlay-canvas", width: W * scale, height: H * scale });
    s.loading = KV.el("div", { id: "stage-loading" }, "loading…");
    const stage = s.stage = KV.el("div", { class: "stage loading", id: "stage", style: `width:${W * scale + 2}px` },
      s.img, s.fill, s.outline, s.canvas, s.loading);
    s.imgError = KV.el("div", { id: "frame-error" });
    s.linkError = KV.el("div", { id: "link-error" });
    s.img.addEventListener("error", async () => {
      if (s) s.stage.classList.remove("loading");
      const url = s.img.src;
      try { await KV.getJSON(url); } catch (err) { if (s) s.imgError.replaceChildren(KV.errorCard("cannot show this frame", err.message)); }
    });
    s.img.addEventListener("load", () => { if (s) { s.imgError.replaceChildren(); s.stage.classList.remove("loading"); } });
    s.canvas.addEventListener("mousemove", (e) => { const px = pixelAt(e); if (px) probe(px[0], px[1]); });
    s.canvas.addEventListener("click", async (e) => {
      const px = pixelAt(e);
      if (!px) return;
      const p = await KV.getJSON(`/api/probe/${encodeURIComponent(name)}/${s.frame}?row=${px[1]}&col=${px[0]}`);
      if (p.instance !== null && p.instance !== undefined) showInstance(p.instance);
    });
    s.readout = KV.el("div", { id: "readout" }, KV.el("span", { class: "muted" }, "hover the image"));
    s.instancePanel = KV.el("div", { id: "instance-panel" }, KV.el("p", { class: "muted" }, "click an object"));
    const canvas3d = KV.el("canvas", { class: "view3d", width: 420, height: 300, id: "view3d" });
    s.rig = KVRig.create(scene, name, W, H);  // a camera rig: its cameras side by side
    const sm = scene.summary, info = scene.metadata.metadata || {};
    const facts = KV.el("div", { class: "kv" },
      ["recipe", sm.recipe, "seed", sm.seed, "split", sm.split, "instances", sm.num_instances,
        "frames", s.T, "resolution", `${W}×${H}`, "background", info.background,
        "spp", (info.renderer || {}).samples_per_pixel, "kubric", ((info.versions || {}).kubric)]
        .map((v, i) => KV.el("span", {}, KV.fmt(v))));
    app.replaceChildren(
      KV.el("a", { href: "#/" }, "← all scenes"),
      sm.error ? KV.errorCard("incomplete scene", sm.error) : "",
      ...buildControls(scene),
      KV.el("div", { class: "layout" },
        KV.el("div", { style: `width:${Math.max(W * scale + 2, 420)}px` }, stage, s.imgError, s.linkError,
          s.rig ? s.rig.element : "",
          KV.el("div", { class: "panel", style: "margin-top:12px" }, KV.el("h3", {}, "reproduce"),
            KV.el("code", { class: "cmd", id: "worker-command" }, scene.worker_command)),
          KV.el("div", { class: "panel", style: "margin-top:12px" }, KV.el("h3", {}, "camera & trajectories"), canvas3d)),
        KV.el("div", { class: "side" },
          KV.el("div", { class: "panel" }, KV.el("h3", {}, "pixel"), s.readout),
          KV.el("div", { class: "panel" }, KV.el("h3", {}, "object"), s.instancePanel),
          KV.el("div", { class: "panel" }, KV.el("h3", {}, "scene"), facts))));
    s.view3d = KV3D.create(canvas3d, scene);
    if (sm.has_tracks) {
      try { s.tracks = await KV.getJSON("/api/tracks/" + encodeURIComponent(name)); } catch (err) {
        s.imgError.append(KV.errorCard("tracks", err.message));
      }
    }
    const first = applyLink(view || {}, s.layers);
    showRange();
    setFrame(first);
    for (let i = 0; i < s.T; i++) if (i !== first) new Image().src = KV.frameUrl(name, s.layer, i);  // warm the cache
  }
  document.addEventListener("keydown", (e) => {  // ← / → step through frames, space plays
    if (!s || e.target.tagName === "INPUT" || e.target.tagName === "SELECT") return;
    if (e.key === "ArrowRight") setFrame(s.frame + 1);
    else if (e.key === "ArrowLeft") setFrame(s.frame - 1);
    else if (e.key === " ") { document.getElementById("play").click(); e.preventDefault(); }
  });
  return { show, stop };
})();
window.KVScene = KVScene;
