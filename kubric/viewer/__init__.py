"""``kubric view``: a read-only dataset viewer in the browser (docs/viewer.md).

* :mod:`kubric.viewer.source` — the :class:`SceneSource` interface and scene directories;
* :mod:`kubric.annotations.pictures` — layer frames → pictures (colour maps, flow wheel, palette);
* :mod:`kubric.viewer.service` — endpoint answers, LRU cache, pixel probe, worker command;
* :mod:`kubric.viewer.server` — the standard-library HTTP server;
* ``static/`` — the page (HTML / JS / CSS, no build step, no network).
"""
