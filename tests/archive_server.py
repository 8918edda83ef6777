"""A real HTTP server on loopback for the download tests (``tests/test_download.py``).

:class:`ArchiveServer` serves in-memory files with byte ranges (``Range: bytes=a-`` / ``a-b``,
``If-Range`` against its ``ETag``; HTTP 206 / 416) and records every request. Switches make it
behave like the servers a download meets: ``ignore_range`` (answers every request with the whole
file), ``stall_at`` (sends the bytes before that offset, then waits until :meth:`release`) and
``drop_at`` (announces the whole length, sends the bytes before that offset, then closes) and
``send_etag`` (False: no validator, so a resume cannot tell that the file changed).
"""

from __future__ import annotations

import hashlib
import http.server
import re
import threading
from dataclasses import dataclass, field


@dataclass
class Request:
    path: str
    range: str | None
    status: int


@dataclass
class ArchiveServer:
    files: dict[str, bytes] = field(default_factory=dict)
    ignore_range: bool = False
    stall_at: int | None = None
    drop_at: int | None = None
    send_etag: bool = True
    requests: list[Request] = field(default_factory=list)

    def __post_init__(self):
        self._released = threading.Event()
        server = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):  # noqa: N802 - http.server naming
                server._serve(self)

            def log_message(self, *args):
                pass

        self._httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self._httpd.daemon_threads = True
        self._thread = threading.Thread(target=self._httpd.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True)

    # --- life cycle -----------------------------------------------------------------------------
    def __enter__(self) -> ArchiveServer:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.release()
        self._httpd.shutdown()
        self._httpd.server_close()
        self._thread.join(5)

    def url(self, name: str) -> str:
        return f"http://127.0.0.1:{self._httpd.server_address[1]}/{name}"

    def release(self) -> None:
        """Let a stalled transfer continue."""
        self._released.set()

    # --- one request ----------------------------------------------------------------------------
    def _serve(self, handler: http.server.BaseHTTPRequestHandler) -> None:
        name = handler.path.lstrip("/")
        asked = handler.headers.get("Range")
        data = self.files.get(name)
        if data is None:
            self.requests.append(Request(handler.path, asked, 404))
            handler.send_error(404, "Not Found")
            return
        etag = f'"{hashlib.sha256(data).hexdigest()[:16]}"'
        start, end, status = 0, len(data), 200
        if_range = handler.headers.get("If-Range")
        m = re.fullmatch(r"bytes=(\d+)-(\d*)", asked or "")
        if m and not self.ignore_range and (if_range is None or if_range == etag):
            start = int(m.group(1))
            end = min(int(m.group(2)) + 1, len(data)) if m.group(2) else len(data)
            if start >= len(data):
                self.requests.append(Request(handler.path, asked, 416))
                handler.send_response(416)
                handler.send_header("Content-Range", f"bytes */{len(data)}")
                handler.send_header("Content-Length", "0")
                handler.end_headers()
                return
            status = 206
        self.requests.append(Request(handler.path, asked, status))
        handler.send_response(status)
        handler.send_header("Content-Type", "application/zip")
        handler.send_header("Content-Length", str(end - start))
        if self.send_etag:
            handler.send_header("ETag", etag)
        handler.send_header("Accept-Ranges", "none" if self.ignore_range else "bytes")
        if status == 206:
            handler.send_header("Content-Range", f"bytes {start}-{end - 1}/{len(data)}")
        handler.end_headers()
        try:
            for cut in sorted({c for c in (self.stall_at, self.drop_at) if c is not None and start < c < end}):
                handler.wfile.write(data[start:cut])
                handler.wfile.flush()
                start = cut
                if cut == self.drop_at:
                    return  # close with the announced length unsent
                self._released.wait(60)
            handler.wfile.write(data[start:end])
        except (BrokenPipeError, ConnectionResetError):
            pass  # the client went away (killed)
