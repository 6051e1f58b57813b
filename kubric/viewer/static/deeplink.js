"use strict";
// Deep links (docs/viewer.md): #/scene/NAME?frame=F&layer=L&overlays=fill,outline&opacity=P
// reopens the same view. The page rewrites the address as the view changes (history.replaceState:
// no reload, no new history entry), so the address bar always links to what is on screen.
const KVLink = {
  OVERLAYS: ["outline", "fill", "boxes", "tracks", "keypoints"],

  // → {route: "list"} or {route: "scene", name, view: {frame?, layer?, overlays?, opacity?}}
  // with the values as written (checked against the scene by KVScene, which says what it refused)
  parse(hash) {
    const h = hash || "#/";
    if (!h.startsWith("#/scene/")) return { route: "list" };
    const rest = h.slice(8), q = rest.indexOf("?");
    const name = decodeURIComponent(q < 0 ? rest : rest.slice(0, q));
    const view = {};
    for (const pair of (q < 0 ? "" : rest.slice(q + 1)).split("&")) {
      if (!pair) continue;
      const at = pair.indexOf("=");
      const key = decodeURIComponent(at < 0 ? pair : pair.slice(0, at));
      const value = at < 0 ? "" : decodeURIComponent(pair.slice(at + 1));
      if (key === "overlays") view.overlays = value ? value.split(",") : [];
      else view[key] = value;
    }
    return { route: "scene", name, view };
  },

  format(name, view) {
    const parts = [`frame=${view.frame}`, `layer=${encodeURIComponent(view.layer)}`];
    parts.push("overlays=" + view.overlays.join(","));  // empty: none (absent: the default)
    parts.push(`opacity=${view.opacity}`);
    return "#/scene/" + encodeURIComponent(name) + "?" + parts.join("&");
  },
};
