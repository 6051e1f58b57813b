"use strict";
// Small DOM and fetch helpers shared by the page's scripts.
const KV = {};

KV.el = function (tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs || {})) {
    if (key === "class") node.className = value;
    else if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
    else if (value !== undefined && value !== null && value !== false) node.setAttribute(key, value);
  }
  for (const child of children.flat()) {
    if (child === null || child === undefined) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
};

KV.getJSON = async function (url) {
  const response = await fetch(url);
  let body;
  try { body = await response.json(); } catch (e) { body = { error: response.statusText }; }
  if (!response.ok) throw new Error(body && body.error ? body.error : response.statusText);
  return body;
};

KV.errorCard = function (title, message) {
  return KV.el("div", { class: "error-card" }, KV.el("b", {}, title + ": "), message);
};

KV.fmt = function (value, digits = 3) {
  if (value === null || value === undefined) return "–";
  if (typeof value === "number") return Number.isInteger(value) ? String(value) : value.toFixed(digits);
  if (Array.isArray(value)) return "(" + value.map((v) => KV.fmt(v, digits)).join(", ") + ")";
  return String(value);
};

KV.rgb = function (colour) { return `rgb(${colour[0]},${colour[1]},${colour[2]})`; };

KV.sceneUrl = (name) => "/api/scene/" + encodeURIComponent(name);
KV.frameUrl = function (name, layer, index, lo, hi) {
  let url = `/api/frame/${encodeURIComponent(name)}/${layer}/${index}.png`;
  const q = [];
  if (lo !== undefined && lo !== null && lo !== "") q.push("lo=" + lo);
  if (hi !== undefined && hi !== null && hi !== "") q.push("hi=" + hi);
  return q.length ? url + "?" + q.join("&") : url;
};
