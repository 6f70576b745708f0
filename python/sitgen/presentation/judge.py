"""The judging page: a local web page that shows two runs of a store side by side and records
which one an expert finds more dangerous (``sitgen judge campaign.db``).

Each run shows as its report page without rank, score or breakdown (so a run is judged by what
happened, not by what it scored): failure class, replay, event timeline, situation figure and
event log. The pair is the most informative one left (:func:`sitgen.triage.weights.next_pair`);
a judgement goes into the store's ``judgements`` table with who made it and when, and the next
pair is chosen with it. Run pages are rendered on first request into a temporary folder (a
run kept as a summary is re-simulated then).

Only this machine's browser may use it, as browsers' DNS-rebinding defences expect of a local
server (:meth:`JudgingServer.refusal`): it is bound to 127.0.0.1; every request must name it
in ``Host`` (a page elsewhere that rebinds its own name to 127.0.0.1 sends its own name); a
judgement must come from the page itself (``Origin`` and ``Sec-Fetch-Site``, where the browser
sends them) and carry the page's token; and a request body is read only up to
:data:`MAX_BODY_BYTES`.
"""

from __future__ import annotations

import contextlib
import html
import json
import secrets
import shutil
import tempfile
import threading
from datetime import UTC, datetime
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

from sitgen.presentation.run_page import run_page
from sitgen.store import WORSE, Judgement, Store
from sitgen.triage.weights import next_pair

MAX_BODY_BYTES = 16 << 10
"""Largest judgement form read (one is under 200 bytes)."""

PAGE_STYLE = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 1em; color: #222; }
h1 { font-size: 1.3em; margin: 0 0 .3em; } .muted { color: #666; }
form { margin: .5em 0 .8em; } button { font-size: 1em; padding: .4em 1em; margin-right: .6em; }
.pair { display: grid; grid-template-columns: 1fr 1fr; gap: 10px; }
.pair h2 { font-size: 1.1em; margin: .2em 0; }
iframe { width: 100%; height: 2200px; border: 1px solid #ccc; }
"""

KEYS_SCRIPT = """
<script>
document.addEventListener('keydown', e => {
  const id = {ArrowLeft: 'worse-a', ArrowRight: 'worse-b', ArrowDown: 'equal'}[e.key];
  if (id) { e.preventDefault(); document.getElementById(id).click(); }
});
</script>
"""


class JudgingServer:
    """The page's HTTP server for store ``db``, judging as ``who``; ``port`` 0 picks a free
    one. ``serve_forever`` serves until ``shutdown``."""

    def __init__(self, db: Path, who: str, port: int = 0) -> None:
        self.db = db
        self.who = who
        self.token = secrets.token_urlsafe(16)
        self.pages = Path(tempfile.mkdtemp(prefix="sitgen-judge-"))
        self.skipped: set[tuple[int, int]] = set()
        self._render_lock = threading.Lock()
        server = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                if not server.refuse(self, write=False):
                    server.get(self)

            def do_POST(self) -> None:
                if not server.refuse(self, write=True):
                    server.post(self)

            def log_message(self, format: str, *args: Any) -> None:
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", port), Handler)

    @property
    def url(self) -> str:
        host, port = self.httpd.server_address[:2]
        return f"http://{host!s}:{port}/"

    def serve_forever(self) -> None:
        self.httpd.serve_forever()

    def shutdown(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        shutil.rmtree(self.pages, ignore_errors=True)

    # Requests.

    def refusal(self, headers: Any, write: bool) -> tuple[HTTPStatus, str] | None:
        """Why a request with ``headers`` is refused (a status and a line), or None: a ``Host``
        that is not this server's address, a write from another origin, or a body that is not
        a length up to :data:`MAX_BODY_BYTES`."""
        port = self.httpd.server_address[1]
        hosts = {f"127.0.0.1:{port}", f"localhost:{port}"}
        host = headers.get("Host")
        if host not in hosts:
            return HTTPStatus.MISDIRECTED_REQUEST, f"Host {host!r} is not this server (127.0.0.1)"
        if not write:
            return None
        origin = headers.get("Origin")
        if origin is not None and origin not in {f"http://{h}" for h in hosts}:
            return HTTPStatus.FORBIDDEN, f"a judgement from another origin ({origin!r})"
        site = headers.get("Sec-Fetch-Site")
        if site is not None and site not in ("same-origin", "none"):
            return HTTPStatus.FORBIDDEN, f"a judgement from a {site} page"
        length = headers.get("Content-Length") or "0"
        if not length.isdigit():
            return HTTPStatus.BAD_REQUEST, f"Content-Length {length!r} is not a length"
        if int(length) > MAX_BODY_BYTES:
            return HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"a body over {MAX_BODY_BYTES} bytes"
        return None

    def refuse(self, request: BaseHTTPRequestHandler, write: bool) -> bool:
        """Answer a refused request (:meth:`refusal`) and close its connection; whether it
        was refused."""
        why = self.refusal(request.headers, write)
        if why is None:
            return False
        request.close_connection = True
        self._send(request, why[0], "text/plain", f"refused: {why[1]}\n".encode())
        return True

    def get(self, request: BaseHTTPRequestHandler) -> None:
        url = urlsplit(request.path)
        if url.path == "/":
            self._send(request, HTTPStatus.OK, "text/html; charset=utf-8", self.page().encode())
        elif url.path == "/judgements.json":
            with Store(self.db) as store:
                rows = [j.as_dict() for j in store.judgements()]
            self._send(request, HTTPStatus.OK, "application/json", json.dumps(rows).encode())
        elif url.path == "/skip":
            query = parse_qs(url.query)
            with contextlib.suppress(KeyError, ValueError):
                self.skipped.add((int(query["a"][0]), int(query["b"][0])))
            self._redirect(request)
        elif url.path.startswith("/runs/"):
            self._run_file(request, url.path.removeprefix("/runs/"))
        else:
            self._send(request, HTTPStatus.NOT_FOUND, "text/plain", b"not found\n")

    def post(self, request: BaseHTTPRequestHandler) -> None:
        if urlsplit(request.path).path != "/judge":
            self._send(request, HTTPStatus.NOT_FOUND, "text/plain", b"not found\n")
            return
        # refusal() has checked the length.
        length = int(request.headers.get("Content-Length") or 0)
        form = parse_qs(request.rfile.read(length).decode("utf-8", "replace"))
        try:
            if form["token"][0] != self.token:
                raise ValueError("token")
            a, b, worse = int(form["a"][0]), int(form["b"][0]), form["worse"][0]
            if worse not in WORSE or a == b:
                raise ValueError("worse")
            with Store(self.db) as store:
                if store.has_runs((a, b)) != {a, b}:
                    raise ValueError("runs")
                at = datetime.now(UTC).isoformat(timespec="seconds")
                store.add_judgements([Judgement(a, b, worse, self.who, at)], "page")
        except (KeyError, ValueError) as e:
            self._send(
                request, HTTPStatus.BAD_REQUEST, "text/plain", f"bad judgement: {e}\n".encode()
            )
            return
        self._redirect(request)

    # Pages.

    def page(self) -> str:
        """The page for the next pair (or the end, when no informative pair is left)."""
        with Store(self.db) as store:
            judged = store.judgements()
            skipped = [Judgement(a, b, "equal") for a, b in self.skipped]
            pair = next_pair(store, judged, exclude=skipped)
        mine = sum(j.who == self.who for j in judged)
        head = (
            f"<p class='muted'>{len(judged)} judgements in {html.escape(self.db.name)} "
            f"({mine} by you, <b>{html.escape(self.who)}</b>). "
            "<a href='/judgements.json'>judgements as JSON</a>. When done: "
            f"<code>sitgen weights fit {html.escape(self.db.name)} -o weights.toml</code></p>"
        )
        if pair is None:
            body = "<h1>No pair left to judge</h1>" + head
            return _page("sitgen judge", body)
        a, b = pair
        body = (
            "<h1>Which run is more dangerous?</h1>" + head + "<form method='post' action='/judge'>"
            f"<input type='hidden' name='token' value='{self.token}'>"
            f"<input type='hidden' name='a' value='{a}'><input type='hidden' name='b' value='{b}'>"
            f"<button id='worse-a' name='worse' value='a'>← run {a} (left)</button>"
            "<button id='equal' name='worse' value='equal'>↓ about equal</button>"
            f"<button id='worse-b' name='worse' value='b'>run {b} (right) →</button>"
            f"<a id='skip' href='/skip?a={a}&b={b}'>skip this pair</a></form>"
            "<div class='pair'>"
            f"<div><h2>Left: run {a}</h2><iframe id='run-a' src='/runs/run-{a}.html' "
            f"title='run {a}'></iframe></div>"
            f"<div><h2>Right: run {b}</h2><iframe id='run-b' src='/runs/run-{b}.html' "
            f"title='run {b}'></iframe></div></div>"
        )
        return _page("sitgen judge", body, KEYS_SCRIPT)

    def _run_file(self, request: BaseHTTPRequestHandler, name: str) -> None:
        """``run-ID.html`` (rendered on first request), its ``.js`` and ``.png``."""
        stem, _, suffix = name.partition(".")
        types = {"html": "text/html; charset=utf-8", "js": "text/javascript", "png": "image/png"}
        try:
            run_id = int(stem.removeprefix("run-"))
        except ValueError:
            run_id = -1
        if suffix not in types or not stem.startswith("run-") or run_id < 0:
            self._send(request, HTTPStatus.NOT_FOUND, "text/plain", b"not found\n")
            return
        path = self.pages / f"run-{run_id}.{suffix}"
        with self._render_lock:
            if not path.exists() and not self._render(run_id):
                self._send(request, HTTPStatus.NOT_FOUND, "text/plain", b"no such run\n")
                return
        self._send(request, HTTPStatus.OK, types[suffix], path.read_bytes())

    def _render(self, run_id: int) -> bool:

        with Store(self.db) as store:
            if not store.has_runs([run_id]):
                return False
            made = run_page(store, run_id, 0, self.pages, self.db.name, blind=True)
        if made is None:
            return False
        page, script = made
        (self.pages / f"run-{run_id}.js").write_text(script)
        (self.pages / f"run-{run_id}.html").write_text(page)
        return True

    @staticmethod
    def _send(
        request: BaseHTTPRequestHandler, status: HTTPStatus, content_type: str, body: bytes
    ) -> None:
        request.send_response(status)
        request.send_header("Content-Type", content_type)
        request.send_header("Content-Length", str(len(body)))
        request.send_header("Cache-Control", "no-store")
        request.end_headers()
        request.wfile.write(body)

    @staticmethod
    def _redirect(request: BaseHTTPRequestHandler) -> None:
        request.send_response(HTTPStatus.SEE_OTHER)
        request.send_header("Location", "/")
        request.send_header("Content-Length", "0")
        request.end_headers()


def _page(title: str, body: str, scripts: str = "") -> str:
    return (
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{title}</title>"
        f"<style>{PAGE_STYLE}</style></head><body>{body}{scripts}</body></html>"
    )
