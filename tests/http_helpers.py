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
        if path in self.server.unannounced or path in self.server.trickle:
            return self._send_raw(path)
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


    def _send_raw(self, path):
        """No Content-Length: half the file then close (``unannounced``), or the whole file a
        byte at a time every ``trickle[path]`` seconds."""
        fh = self.send_head()
        if fh is None:
            return
        with fh:
            data = fh.read()
        self.close_connection = True
        if path in self.server.unannounced:
            self.wfile.write(data[: len(data) // 2])
            return
        for i in range(len(data)):
            self.wfile.write(data[i:i + 1])
            self.wfile.flush()
            time.sleep(self.server.trickle[path])

    def send_header(self, keyword, value):
        path = self.path.split("?", 1)[0]
        if keyword == "Content-Length" and (path in self.server.unannounced
                                            or path in self.server.trickle):
            return
        super().send_header(keyword, value)


class _Server(http.server.ThreadingHTTPServer):
    daemon_threads = True


@contextlib.contextmanager
def serve(folder):
    """Serve ``folder`` on a free 127.0.0.1 port; yields the server, with ``url`` (no trailing
    slash), ``gets`` (a Counter of GET paths) and the dicts ``delay`` {path: seconds},
    ``status`` {path: code}, the set ``cut`` {path} (full Content-Length, half the bytes), the set
    ``unannounced`` {path} (no Content-Length, half the bytes) and ``trickle`` {path: seconds per
    byte, no Content-Length} to change its behaviour."""
    handler = lambda *a, **k: _Handler(*a, directory=str(folder), **k)
    server = _Server(("127.0.0.1", 0), handler)
    server.gets, server.lock = Counter(), threading.Lock()
    server.delay, server.status, server.cut = {}, {}, set()
    server.unannounced, server.trickle = set(), {}
    server.url = f"http://127.0.0.1:{server.server_address[1]}"
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=10)
