"use strict";
// A camera rig's cameras side by side (docs/conventions.md#camera-rigs): under the stage, one
// picture per camera of the layer on the stage at the current frame — the reference camera's
// LAYER, camera NAME's NAME_LAYER (its RGB when the scene holds no NAME_LAYER) — each captioned
// with its camera, layer and frame. Nothing for a one-camera scene.
const KVRig = (function () {
  function create(scene, name, W, H) {
    const rig = (scene.metadata.camera || {}).rig;
    if (!rig || !Array.isArray(rig.cameras) || rig.cameras.length < 2) return null;
    const layers = scene.summary.layers || [];
    const budget = Math.max(150, Math.floor(580 / rig.cameras.length) - 10);  // px per tile
    const k = Math.max(1, Math.floor(Math.min(budget / W, 220 / H)));
    const tiles = rig.cameras.map((camera, c) => {
      const img = KV.el("img", { id: `rig-img-${camera}`, width: W * k, height: H * k, alt: camera });
      const caption = KV.el("figcaption", { class: "muted" }, camera);
      return { camera, prefix: c === 0 ? "" : camera + "_", img, caption,
        el: KV.el("figure", { class: "rig-camera", "data-camera": camera }, img, caption) };
    });
    const baseline = rig.baseline ? `, baseline ${KV.fmt(rig.baseline)} m` : "";
    const element = KV.el("div", { class: "panel", id: "rig-panel", style: "margin-top:12px" },
      KV.el("h3", {}, `camera rig: ${rig.kind} (${rig.cameras.join(", ")}${baseline})`),
      KV.el("div", { class: "rig-row" }, tiles.map((t) => t.el)));

    function show(frame, layer) {
      for (const t of tiles) {
        const own = layers.includes(t.prefix + layer) ? t.prefix + layer : t.prefix + "rgba";
        const url = KV.frameUrl(name, own, frame);
        if (t.img.getAttribute("src") !== url) t.img.src = url;
        t.img.dataset.layer = own;
        t.caption.textContent = `${t.camera} · ${own} · frame ${frame}`;
      }
    }
    return { element, show };
  }
  return { create };
})();
