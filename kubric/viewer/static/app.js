"use strict";
// Hash routing: #/ is the scene list, #/scene/NAME one scene.
(function () {
  const app = document.getElementById("app");
  function route() {
    const hash = location.hash || "#/";
    if (window.KVScene && KVScene.stop) KVScene.stop();
    if (hash.startsWith("#/scene/")) KVScene.show(app, decodeURIComponent(hash.slice(8)));
    else KVList.show(app);
  }
  window.addEventListener("hashchange", route);
  route();
})();
