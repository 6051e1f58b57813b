"use strict";
// Hash routing: #/ is the scene list, #/scene/NAME[?frame=&layer=&overlays=&opacity=] one scene
// (deeplink.js).
(function () {
  const app = document.getElementById("app");
  function route() {
    const link = KVLink.parse(location.hash);
    if (window.KVScene && KVScene.stop) KVScene.stop();
    if (link.route === "scene") KVScene.show(app, link.name, link.view);
    else KVList.show(app);
  }
  window.addEventListener("hashchange", route);
  route();
})();
