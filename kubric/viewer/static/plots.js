"use strict";
// A small visibility-over-time plot (canvas 2D): visible pixels per frame, current frame marked.
const KVPlot = {
  visibility(canvas, values, current, colour) {
    const ctx = canvas.getContext("2d");
    const w = canvas.width, h = canvas.height, pad = 18;
    ctx.clearRect(0, 0, w, h);
    const max = Math.max(1, ...values);
    const n = values.length;
    const x = (i) => pad + (n > 1 ? i / (n - 1) : 0.5) * (w - 2 * pad);
    const y = (v) => h - pad - (v / max) * (h - 2 * pad);
    ctx.strokeStyle = "#444"; ctx.beginPath();
    ctx.moveTo(pad, h - pad); ctx.lineTo(w - pad, h - pad); ctx.moveTo(pad, pad); ctx.lineTo(pad, h - pad);
    ctx.stroke();
    ctx.fillStyle = "#8a909c"; ctx.font = "10px sans-serif";
    ctx.fillText(String(max) + " px", pad + 2, pad - 6);
    ctx.fillText("frame " + (n - 1), w - pad - 40, h - 4);
    ctx.fillText("0", pad - 2, h - 4);
    ctx.strokeStyle = "#e4e6ea"; ctx.beginPath(); ctx.moveTo(x(current), pad); ctx.lineTo(x(current), h - pad);
    ctx.stroke();
    ctx.strokeStyle = colour; ctx.fillStyle = colour; ctx.lineWidth = 2; ctx.beginPath();
    values.forEach((v, i) => (i ? ctx.lineTo(x(i), y(v)) : ctx.moveTo(x(i), y(v))));
    ctx.stroke(); ctx.lineWidth = 1;
    values.forEach((v, i) => { ctx.beginPath(); ctx.arc(x(i), y(v), 2.5, 0, 2 * Math.PI); ctx.fill(); });
  },
};
