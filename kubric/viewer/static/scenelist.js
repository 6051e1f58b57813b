"use strict";
// The scene list: thumbnails, filter, sort by any column; scenes that cannot be shown say why.
const KVList = (function () {
  const COLUMNS = [
    ["name", "scene"], ["recipe", "recipe"], ["seed", "seed"], ["split", "split"],
    ["num_instances", "instances"], ["num_frames", "frames"], ["resolution", "resolution"],
    ["has_tracks", "tracks"], ["error", "status"],
  ];
  const state = { scenes: [], sortKey: "name", sortDir: 1, filter: "" };

  function cell(row, key) {
    const value = row[key];
    if (key === "resolution") return value ? value.join("×") : "–";
    if (key === "has_tracks") return value ? "yes" : "";
    if (key === "error") return value ? value : "ok";
    return value === null || value === undefined ? "–" : value;
  }

  function compare(a, b) {
    let x = a[state.sortKey], y = b[state.sortKey];
    if (Array.isArray(x)) x = x[0] * x[1];
    if (Array.isArray(y)) y = y[0] * y[1];
    if (x === y) return a.name < b.name ? -1 : 1;
    if (x === null || x === undefined) return 1;
    if (y === null || y === undefined) return -1;
    return (x < y ? -1 : 1) * state.sortDir;
  }

  function matches(row) {
    if (!state.filter) return true;
    const text = COLUMNS.map(([key]) => String(cell(row, key))).join(" ").toLowerCase();
    return state.filter.toLowerCase().split(/\s+/).every((word) => text.includes(word));
  }

  function renderTable(container) {
    const rows = state.scenes.filter(matches).sort(compare);
    const head = KV.el("tr", {}, KV.el("th", {}, ""), COLUMNS.map(([key, label]) =>
      KV.el("th", {
        class: key === state.sortKey ? "sorted" : "", "data-key": key,
        onclick: () => {
          state.sortDir = key === state.sortKey ? -state.sortDir : 1;
          state.sortKey = key;
          renderTable(container);
        },
      }, label + (key === state.sortKey ? (state.sortDir > 0 ? " ▲" : " ▼") : ""))));
    const body = rows.map((row) => KV.el("tr", {
      class: "scene-row", "data-name": row.name,
      onclick: () => { location.hash = "#/scene/" + encodeURIComponent(row.name); },
    },
    KV.el("td", { class: "thumb" }, row.layers.includes("rgba") && !row.error ?
      KV.el("img", { loading: "lazy", alt: "", src: KV.frameUrl(row.name, "rgba", 0) }) : ""),
    COLUMNS.map(([key]) => KV.el("td", { class: key === "error" && row.error ? "status-bad" : "" },
      cell(row, key)))));
    container.replaceChildren(KV.el("table", { id: "scene-table" }, KV.el("thead", {}, head),
      KV.el("tbody", {}, body)));
    document.getElementById("scene-count").textContent =
      `${rows.length} of ${state.scenes.length} scene(s)`;
  }

  async function show(app) {
    document.getElementById("crumb").textContent = "";
    const tableBox = KV.el("div", {}, KV.el("p", { class: "muted" }, "loading the scene list…"));
    const filter = KV.el("input", {
      type: "search", id: "filter", placeholder: "filter: recipe, seed, split, status…",
      value: state.filter, size: 40,
      oninput: (e) => { state.filter = e.target.value; renderTable(tableBox); },
    });
    app.replaceChildren(KV.el("div", { class: "toolbar" }, filter,
      KV.el("span", { id: "scene-count", class: "muted" }, "")), tableBox);
    try {
      state.scenes = (await KV.getJSON("/api/scenes")).scenes;
    } catch (err) {
      app.replaceChildren(KV.errorCard("cannot list scenes", err.message));
      return;
    }
    renderTable(tableBox);
  }
  return { show };
})();
