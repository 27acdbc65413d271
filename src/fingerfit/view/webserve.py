"""Rerun's web viewer served to the browser from ``127.0.0.1`` only, with a
Content-Security-Policy that keeps the page on this machine (``fingerfit view --web``).

Nothing listens beyond this machine. rerun-sdk 0.41's Python web-viewer server
(``rerun.serve_web_viewer``) binds every interface, with no option to say otherwise; the
``rerun`` command of the same wheel binds its web viewer where ``--bind`` says. So the
viewer's files come from that command, started by :class:`LocalViewerServer` as
``rerun URL --serve-web --bind 127.0.0.1`` on a port of the system's choosing (with a URL
to view it hosts the viewer alone: no gRPC server of its own), and the data from Rerun's
gRPC server bound to ``127.0.0.1`` too (:func:`serve_grpc_local`).

Rerun 0.41's web viewer, once in a browser, asks hosts beyond this machine for its usage
events (``tel.rerun.io``), its examples list (``app.rerun.io``), its release check
(``api.github.com``) and web fonts (Google); the ``CI`` variable that turns Rerun's
analytics off (:func:`fingerfit.view.no_usage_reporting`) does not reach a browser. So
the browser gets the viewer from :class:`ViewerProxy`, a small HTTP server of ours on
``127.0.0.1`` that forwards each request to the viewer's server and adds
:func:`content_security_policy` to every response: the browser itself then refuses any
request to another host, before resolving its name.
"""

from __future__ import annotations

import http.client
import http.server
import importlib.util
import os
import socket
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

from ..errors import FingerfitError

#: The address every server of ours binds to: this machine only.
LOCAL_HOST = "127.0.0.1"

#: Response headers not forwarded: per-connection ones, a policy of Rerun's own (ours
#: replaces it), and the server's name and date (this server sends its own).
_HOP_BY_HOP = frozenset(
    {
        "server",
        "date",
        "connection",
        "keep-alive",
        "proxy-authenticate",
        "proxy-authorization",
        "te",
        "trailers",
        "transfer-encoding",
        "upgrade",
        "content-security-policy",
    }
)


def free_port() -> int:
    """A TCP port free on ``127.0.0.1`` now (the system's pick)."""
    with socket.socket() as s:
        s.bind((LOCAL_HOST, 0))
        return int(s.getsockname()[1])


def content_security_policy(grpc_port: int) -> str:
    """The policy every response of :class:`ViewerProxy` carries.

    The page may load its scripts, styles, WebAssembly, workers, fonts and images from
    itself (or as ``data:``/``blob:``), and connect to itself and to the data on
    ``127.0.0.1:grpc_port`` (gRPC-web over HTTP, or a websocket); nothing else. A
    request to any other host is refused by the browser before it is sent.

    Parameters
    ----------
    grpc_port : int
        The port of Rerun's gRPC server, on ``127.0.0.1``.

    Returns
    -------
    str
        The header's value.
    """
    data = " ".join(
        f"{scheme}://{host}:{grpc_port}"
        for scheme in ("http", "ws")
        for host in (LOCAL_HOST, "localhost")
    )
    return "; ".join(
        [
            "default-src 'self'",
            "script-src 'self' 'unsafe-inline' 'wasm-unsafe-eval'",
            "style-src 'self' 'unsafe-inline'",
            f"connect-src 'self' {data}",
            "img-src 'self' data: blob:",
            "font-src 'self' data:",
            "worker-src 'self' blob:",
            "manifest-src 'self'",
            "frame-src 'none'",
            "object-src 'none'",
            "base-uri 'self'",
            "form-action 'self'",
        ]
    )


class _Forward(http.server.BaseHTTPRequestHandler):
    """Forwards GET and HEAD to Rerun's web-viewer server, adding the policy."""

    server: ViewerProxy
    protocol_version = "HTTP/1.1"

    def do_GET(self) -> None:
        self._forward(body=True)

    def do_HEAD(self) -> None:
        self._forward(body=False)

    def _forward(self, body: bool) -> None:
        upstream = http.client.HTTPConnection(LOCAL_HOST, self.server.upstream_port, timeout=60)
        headers = {k: v for k, v in self.headers.items() if k.lower() not in _HOP_BY_HOP | {"host"}}
        try:
            upstream.request(self.command, self.path, headers=headers)
            reply = upstream.getresponse()
            content = reply.read()
        except OSError as exc:
            self.send_error(502, f"Rerun's web viewer server: {exc}")
            return
        finally:
            upstream.close()
        self.send_response(reply.status, reply.reason)
        for k, v in reply.getheaders():
            if k.lower() not in _HOP_BY_HOP | {"content-length"}:
                self.send_header(k, v)
        self.send_header("Content-Security-Policy", self.server.policy)
        self.send_header("Content-Length", str(len(content)))
        self.end_headers()
        if body:
            self.wfile.write(content)

    def log_message(self, format: str, *args: Any) -> None:
        """Quiet: the command's output is its own."""


class ViewerProxy(http.server.ThreadingHTTPServer):
    """An HTTP server on ``127.0.0.1`` forwarding to Rerun's web-viewer server, each
    response with :func:`content_security_policy`; it serves in a daemon thread.

    Parameters
    ----------
    port : int
        Its port on ``127.0.0.1`` (the one to open; 0: the system's pick, see
        :attr:`port`).
    upstream_port : int
        The port of the web viewer's server (:class:`LocalViewerServer`), reached on
        ``127.0.0.1``.
    grpc_port : int
        The port of Rerun's gRPC server on ``127.0.0.1``: the only other place the page
        may connect to.

    Attributes
    ----------
    port : int
        The port it listens on.
    policy : str
        The Content-Security-Policy it adds.

    Raises
    ------
    OSError
        The port is taken.
    """

    daemon_threads = True

    def __init__(self, port: int, upstream_port: int, grpc_port: int) -> None:
        super().__init__((LOCAL_HOST, port), _Forward)
        self.upstream_port = upstream_port
        self.policy = content_security_policy(grpc_port)
        self.port = int(self.server_address[1])
        self._thread = threading.Thread(
            target=self.serve_forever, name="fingerfit-web-proxy", daemon=True
        )
        self._thread.start()

    def url(self, data_uri: str) -> str:
        """The address to open: the viewer, connected to ``data_uri`` (Rerun's gRPC)."""
        from urllib.parse import quote

        return f"http://{LOCAL_HOST}:{self.port}/?url={quote(data_uri, safe='')}"

    def close(self) -> None:
        """Stop serving and release the port."""
        self.shutdown()
        self.server_close()
        self._thread.join()


def serve_grpc_local(stream: Any, grpc_port: int, default_blueprint: Any = None) -> str:
    """Serve a Rerun recording stream over gRPC on ``127.0.0.1:grpc_port`` only.

    Parameters
    ----------
    stream : rerun.RecordingStream
    grpc_port : int
    default_blueprint : rerun.blueprint.Blueprint, optional

    Returns
    -------
    str
        The server's address for a viewer (``rerun+http://127.0.0.1:PORT/proxy``).
    """
    import rerun as rr

    sink = rr.GrpcServerSink(LOCAL_HOST, grpc_port)
    stream.set_sinks(sink, default_blueprint=default_blueprint)
    return str(sink.uri)


#: Seconds the ``rerun`` command has to start serving before :class:`LocalViewerServer`
#: gives up.
START_TIMEOUT_S = 60.0


def rerun_command() -> Path:
    """The ``rerun`` command of the installed rerun-sdk wheel (package ``rerun_cli``).

    Raises
    ------
    FingerfitError
        The wheel has none (the extra ``view`` not installed, or a build without it).
    """
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin is not None:
        exe = Path(spec.origin).parent / ("rerun.exe" if os.name == "nt" else "rerun")
        if exe.is_file():
            return exe
    raise FingerfitError(
        "the rerun command of rerun-sdk is missing (pip install fingerfit[view])", field="--web"
    )


class LocalViewerServer:
    """Rerun's web viewer (its files: page, script, WebAssembly) served over HTTP on
    ``127.0.0.1`` by the ``rerun`` command, in a process of its own, its usage reporting
    off (module docstring).

    Parameters
    ----------
    connect_to : str
        The data the viewer shows (``rerun+http://127.0.0.1:PORT/proxy``).
    port : int
        Its port on ``127.0.0.1`` (0: the system's pick).

    Attributes
    ----------
    port : int
        The port it listens on.
    pid : int
        The command's process.

    Raises
    ------
    FingerfitError
        The command is missing, or did not start serving (its last words in the message).
    """

    def __init__(self, connect_to: str, port: int = 0) -> None:
        import tempfile

        from .scene import NO_ANALYTICS_ENV

        self.port = port or free_port()
        self._said = ""
        env = {**os.environ, **NO_ANALYTICS_ENV}
        env.pop("FORCE_RERUN_ANALYTICS", None)
        args = [str(rerun_command()), connect_to, "--serve-web", "--bind", LOCAL_HOST]
        self._log = tempfile.TemporaryFile()  # what it says, read only if it fails
        self._proc = subprocess.Popen(
            [*args, "--web-viewer-port", str(self.port)],
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=env,
        )
        self.pid = int(self._proc.pid)
        deadline = time.monotonic() + START_TIMEOUT_S
        while not _accepts(self.port):
            if self._proc.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise FingerfitError(
                    f"Rerun's web viewer did not start on {LOCAL_HOST}:{self.port}"
                    + (f" ({self._said})" if self._said else ""),
                    field="--web",
                )
            time.sleep(0.05)

    def close(self) -> None:
        """Stop the command (at once: it holds nothing to save) and wait for it."""
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        if not self._log.closed:
            self._log.seek(0)
            lines = [ln.strip() for ln in self._log.read().decode("utf-8", "replace").splitlines()]
            self._said = next((ln[-200:] for ln in reversed(lines) if ln), "")
            self._log.close()


def _accepts(port: int) -> bool:
    """Whether something accepts TCP connections on ``127.0.0.1:port`` now."""
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex((LOCAL_HOST, port)) == 0
