"use strict";
// A small 3D view (canvas 2D, orthographic, drag to orbit): the floor grid at z = 0, the camera's
// path with its viewing direction at the current frame, a camera rig's further cameras (grey,
// named, joined to the reference camera at the current frame), and every object's trajectory with
// its position at the current frame. World z is up.
const KV3D = (function () {
  const RIG_COLOUR = "#9aa4b2";
  function create(canvas, scene) {
    const view = { yaw: -0.6, pitch: 0.35, frame: 0, selected: null };
    const cam = scene.metadata.camera || {};
    const instances = scene.metadata.instances || [];
    const paths = instances.map((inst) => inst.positions || []);
    const camPath = cam.positions || [];
    const rigViews = Object.entries((cam.rig || {}).views || {});  // [name, camera record]
    const all = [].concat(camPath, ...paths, ...rigViews.map(([, v]) => v.positions || []));
    const centre = [0, 1, 2].map((k) => all.length ? all.reduce((s, p) => s + p[k], 0) / all.length : 0);
    centre[2] = 0;
    const extent = Math.max(1, ...all.map((p) => Math.hypot(p[0] - centre[0], p[1] - centre[1], p[2])));
    if (camPath.length) {  // start looking from the side of the camera's line of sight
      view.yaw = 0.5 - Math.atan2(camPath[0][1] - centre[1], camPath[0][0] - centre[0]);
    }

    function project(p) {
      const x0 = p[0] - centre[0], y0 = p[1] - centre[1], z0 = p[2] - centre[2];
      const cy = Math.cos(view.yaw), sy = Math.sin(view.yaw);
      const x = cy * x0 - sy * y0, y = sy * x0 + cy * y0;
      const up = z0 * Math.cos(view.pitch) + y * Math.sin(view.pitch);
      const s = (Math.min(canvas.width, canvas.height) / 2 - 10) / extent;
      return [canvas.width / 2 + x * s, canvas.height / 2 - up * s];
    }

    function polyline(ctx, points, colour, width) {
      if (!points.length) return;
      ctx.strokeStyle = colour; ctx.lineWidth = width; ctx.beginPath();
      points.forEach((p, i) => { const q = project(p); if (i) ctx.lineTo(q[0], q[1]); else ctx.moveTo(q[0], q[1]); });
      ctx.stroke(); ctx.lineWidth = 1;
    }

    function dot(ctx, p, colour, r) {
      const q = project(p);
      ctx.fillStyle = colour; ctx.beginPath(); ctx.arc(q[0], q[1], r, 0, 2 * Math.PI); ctx.fill();
    }

    // a camera's path, its position (a dot) and viewing direction at the current frame; returns
    // that position (undefined when the record has none at this frame)
    function camera(ctx, record, colour) {
      const path = record.positions || [];
      polyline(ctx, path, colour, 1.5);
      const here = path[view.frame];
      if (!here) return here;
      const m = (record.matrices_world || [])[view.frame];
      if (m) {  // the camera looks down its -z axis: third column of the rotation, negated
        const len = extent * 0.25;
        polyline(ctx, [here, [here[0] - m[0][2] * len, here[1] - m[1][2] * len, here[2] - m[2][2] * len]], "#ffd24a", 2);
      }
      dot(ctx, here, colour, 4);
      return here;
    }

    function draw() {
      const ctx = canvas.getContext("2d");
      ctx.clearRect(0, 0, canvas.width, canvas.height);
      const step = Math.pow(10, Math.floor(Math.log10(extent)));
      const n = Math.ceil(extent / step);
      ctx.strokeStyle = "#2a2e36";
      for (let i = -n; i <= n; i++) {
        polyline(ctx, [[centre[0] + i * step, centre[1] - n * step, 0], [centre[0] + i * step, centre[1] + n * step, 0]], "#2a2e36", 1);
        polyline(ctx, [[centre[0] - n * step, centre[1] + i * step, 0], [centre[0] + n * step, centre[1] + i * step, 0]], "#2a2e36", 1);
      }
      polyline(ctx, [centre, [centre[0] + step, centre[1], 0]], "#c44", 2);
      polyline(ctx, [centre, [centre[0], centre[1] + step, 0]], "#4c4", 2);
      polyline(ctx, [centre, [centre[0], centre[1], step]], "#48f", 2);
      paths.forEach((path, k) => {
        const colour = KV.rgb(scene.palette[k + 1]);
        polyline(ctx, path, colour, view.selected === k ? 3 : 1.5);
        if (path[view.frame]) dot(ctx, path[view.frame], colour, view.selected === k ? 5 : 3);
      });
      const reference = camPath[view.frame];
      for (const [, record] of rigViews) {  // the rig: each camera joined to the reference
        const p = (record.positions || [])[view.frame];
        if (reference && p) polyline(ctx, [reference, p], RIG_COLOUR, 1);
      }
      camera(ctx, cam, "#ffffff");
      const drawn = {};
      for (const [name, record] of rigViews) {
        const p = camera(ctx, record, RIG_COLOUR);
        if (!p) continue;
        const q = project(p);
        ctx.fillStyle = RIG_COLOUR; ctx.font = "10px sans-serif"; ctx.fillText(name, q[0] + 6, q[1] - 6);
        drawn[name] = q;
      }
      canvas.dataset.rig = JSON.stringify(drawn);  // {camera name: [x, y] on the canvas}
      ctx.fillStyle = "#8a909c"; ctx.font = "10px sans-serif";
      ctx.fillText("drag to orbit · white: camera" + (rigViews.length ? " · grey: the rig's other cameras" : "") +
        " · grid " + step + " m", 6, canvas.height - 6);
    }

    let drag = null;
    canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY, view.yaw, view.pitch]; });
    window.addEventListener("mouseup", () => { drag = null; });
    canvas.addEventListener("mousemove", (e) => {
      if (!drag) return;
      view.yaw = drag[2] + (e.clientX - drag[0]) * 0.01;
      view.pitch = Math.max(-0.1, Math.min(Math.PI / 2, drag[3] + (e.clientY - drag[1]) * 0.01));
      draw();
    });
    draw();
    return {
      setFrame(frame) { view.frame = frame; draw(); },
      select(k) { view.selected = k; draw(); },
    };
  }
  return { create };
})();
