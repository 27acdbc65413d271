"""Rerun's web viewer served to the browser from ``127.0.0.1`` only, with a
Content-Security-Policy that keeps the page on this machine (``fingerfit view --web``).

Rerun 0.41's web viewer, once in a browser, asks hosts beyond this machine for its usage
events (``tel.rerun.io``), its examples list (``app.rerun.io``), its release check
(``api.github.com``) and web fonts (Google); the ``CI`` variable that turns Rerun's
analytics off (:func:`fingerfit.view.no_usage_reporting`) does not reach a browser. So
the browser gets the viewer from :class:`ViewerProxy`, a small HTTP server of ours on
``127.0.0.1`` that forwards each request to Rerun's web-viewer server and adds
:func:`content_security_policy` to every response: the browser itself then refuses any
request to another host, before resolving its name. The data (Rerun's gRPC server) is
bound to ``127.0.0.1`` too (:func:`serve_grpc_local`). Rerun's own web-viewer server has
no bind option in rerun-sdk 0.41 and listens on every interface, on a port of the
system's choosing that fingerfit neither prints nor opens.
"""

from __future__ import annotations

import http.client
import http.server
import socket
import threading
from typing import Any

#: The address every server of ours binds to: this machine only.
LOCAL_HOST = "127.0.0.1"

#: Response headers not forwarded: per-connection ones, and a policy of Rerun's own
#: (ours replaces it).
_HOP_BY_HOP = frozenset(
    {
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
        The port of Rerun's web-viewer server (``rerun.serve_web_viewer``), reached on
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
