"""A real HTTP server on 127.0.0.1 (the standard library's, in a thread) serving a folder, with
knobs for the failures a download must survive: a slow answer, a connection cut half way, a
fixed status. Every GET is recorded, so tests can count downloads."""

import contextlib
import http.server
import threading
import time
from collections import Counter


class _Handler(http.server.SimpleHTTPRequestHandler):
    server: "_Server"

    def log_message(self, *args):  # quiet
        pass

    def do_GET(self):  # noqa: N802 - the standard library's name
        path = self.path.split("?", 1)[0]
        with self.server.lock:
            self.server.gets[path] += 1
        time.sleep(self.server.delay.get(path, 0.0))
        status = self.server.status.get(path)
        if status is not None:
            self.send_error(status)
            return
        if path not in self.server.cut:
            return super().do_GET()
        fh = self.send_head()  # headers with the full Content-Length
        if fh is None:
            return
        with fh:
            data = fh.read()
        self.wfile.write(data[: len(data) // 2])
        self.wfile.flush()
        self.close_connection = True


class _Server(http.server.ThreadingHTTPServer):
    daemon_threads = True


@contextlib.contextmanager
def serve(folder):
    """Serve ``folder`` on a free 127.0.0.1 port; yields the server, with ``url`` (no trailing
    slash), ``gets`` (a Counter of GET paths) and the dicts ``delay`` {path: seconds},
    ``status`` {path: code} and the set ``cut`` {path} to change its behaviour."""
    handler = lambda *a, **k: _Handler(*a, directory=str(folder), **k)
    server = _Server(("127.0.0.1", 0), handler)
    server.gets, server.lock = Counter(), threading.Lock()
    server.delay, server.status, server.cut = {}, {}, set()
    server.url = f"http://127.0.0.1:{server.server_address[1]}"
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=10)
